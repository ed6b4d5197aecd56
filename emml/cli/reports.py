"""Reports and figures: `emml report`, `reports`, `backfill-config`, `import-runs`, `video` and
`emml visualize ...` (emml/report/)."""

from __future__ import annotations

from pathlib import Path

import typer

from emml.cli.common import (
    JSON_HELP,
    Task,
    _check_store,
    _echo,
    _fail,
    _models,
    _out,
    _own_engines,
    profile_option,
    table_argument,
)

READ_RUN_ROOT_HELP = "Folder of the run dirs the report reads (default: the profile's, the checkout's runs/)."
READ_RESULTS_ROOT_HELP = "Folder of the results CSVs the report reads (default: the profile's, results/)."


def report(
    table: str = table_argument("table2 | table3 | table4 | table5, or a table file of your own (x.toml)."),
    profile: str = profile_option(help="Whose results are reported."),
    curves: bool = typer.Option(True, "--curves/--no-curves", help="Also plot training curves (needs MLflow)."),
    out: Path = typer.Option(None, help="Output folder (default: reports/; smoke: scratch/reports/)."),
    run_root: str = typer.Option(None, help=READ_RUN_ROOT_HELP),
    results_root: str = typer.Option(None, help=READ_RESULTS_ROOT_HELP),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """One table, ours beside the paper's numbers.

    Writes reports/TABLE-PROFILE.md and .tex (the mean over seeds with each seed's value beside the paper's, the
    runs' deviations from the paper, an rliable aggregate) and TABLE-PROFILE-curves.png/.pdf."""
    from emml.models.plugins import configured
    from emml.report.tables import report_table
    from emml.runs.diskspace import NoSpaceError

    if curves:  # they read MLflow
        _check_store()
    try:
        if table.endswith(".toml"):  # a table of one's own: reported by its name, the file's stem
            from emml.experiments.table_files import own_table

            table = own_table(table)
        roots = {"results_root": results_root, "run_root": run_root}
        # a table of one's own may need its plugin: the page's "Made by" line carries it (issue 64)
        data = report_table(table, profile, out=_out(out) if out else None, plugins=configured(), **roots)
    except (ValueError, NoSpaceError) as e:  # NoSpaceError: a full disk, the folder named, each file old or new
        _fail(str(e))
    data["notes"] = []
    if curves:
        from emml.report.curves import plot_table

        paths, notes = plot_table(table, profile, out=_out(out) if out else None, **roots)
        data["paths"] += [str(p) for p in paths]
        data["notes"] = notes
    text = "\n".join([data["caption"], *[f"note: {n}" for n in data["notes"]], *[f"wrote {p}" for p in data["paths"]]])
    _echo(data, as_json, text)


def reports(
    out: Path = typer.Option(None, help="Output folder (default: reports/)."),
    run_root: str = typer.Option(None, help=READ_RUN_ROOT_HELP),
    results_root: str = typer.Option(None, help=READ_RESULTS_ROOT_HELP),
):
    """Every table, curve and figure, and reports/index.md linking them.

    For every profile with results but smoke."""
    from emml.report.index import write_reports

    _check_store()  # the curves read MLflow
    _own_engines()
    from emml.runs.diskspace import NoSpaceError

    try:  # a damaged run dir is named and skipped inside; what is left (a results CSV, the claims) fails in one line
        roots = {k: v for k, v in (("results_root", results_root), ("run_root", run_root)) if v is not None}
        index = write_reports(_out(out) if out else None, log=typer.echo, **roots)
    except (ValueError, NoSpaceError) as e:  # a full disk: the folder named, each file written old or new
        _fail(str(e))
    typer.echo(f"wrote {index}")


def backfill_config(
    paths: list[Path] = typer.Argument(..., help="Run dirs, or folders holding them (e.g. runs/table2)."),
):
    """Copy finished runs' configs from their checkpoints into their results.json.

    For runs finished before the trainer wrote it there: reports then read the deviations from the paper without
    loading checkpoints. A run still training is skipped."""
    from emml.config.paths import project_path
    from emml.report.saved_config import backfill_config as backfill
    from emml.report.saved_config import run_dirs

    found = run_dirs([project_path(p) for p in paths])
    if not found:
        _fail(f"no run dir (a folder with checkpoint.pt) at or under {', '.join(map(str, paths))}")
    for run_dir in found:
        typer.echo(f"{run_dir}: {backfill(run_dir)}")


def import_runs_cmd(
    paths: list[Path] = typer.Argument(None, help="Run dirs, or folders holding them (default: the run root)."),
    run_root: Path = typer.Option(Path("runs"), help="The folder whose run dirs are imported when no path is given."),
    results_root: Path = typer.Option(
        Path("results"),
        help="The folder of this checkout holding the runs' results rows: the results_root param of each run whose "
        "own results root was a results/ folder (on the machine that trained it).",
    ),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Import finished run dirs into the MLflow store (`make ui` shows them).

    One FINISHED run each, in its table's experiment, with the trainer's tags, its config as params, every point
    of its evaluation curves (eval/*, diag/*) and its score (final/*), 100 evenly spaced points of each per-update
    key (losses, charts) and its whole metrics.csv as an artifact, dated when it trained (a progress bar on a
    terminal). Once, even with two
    imports at once or after one was killed: a run already in the store (trained or imported here) is skipped, and
    so is an unfinished one (its trainer logs it)."""
    from emml.config.paths import project_path
    from emml.runs.import_runs import import_runs
    from emml.runs.store import tracking_uri

    roots = [project_path(p) for p in paths] if paths else [project_path(run_root)]
    missing = [str(p) for p in roots if not p.exists() and (paths or run_root != Path("runs"))]
    if missing:
        _fail(f"no such run dir or folder: {', '.join(missing)}" + ("" if paths else " (--run-root)"))
    if project_path(results_root).exists() and not project_path(results_root).is_dir():
        _fail(f"--results-root: {results_root} is not a folder")
    _check_store()
    from emml.envs.engine import install_signal_handlers
    from emml.experiments.launch import stop_cause
    from emml.runs.diskspace import NoSpaceError

    install_signal_handlers()  # SIGTERM ends it as Ctrl-C does: the run being imported deleted, exit 130
    done: list = []

    def log(r):
        done.append(r)
        if not as_json:
            typer.echo(r.line())

    try:
        results = import_runs(roots, log=log, progress=not as_json, results_root=results_root)
    except NoSpaceError as e:
        _fail(str(e))
    except (KeyboardInterrupt, SystemExit) as e:
        if stop_cause(e) is None:
            raise
        typer.echo(
            f"stopped by {stop_cause(e)}: {sum(r.outcome == 'imported' for r in done)} run dirs imported, the one "
            "being imported removed from the store; resume with the same command (what is imported is skipped)"
        )
        raise typer.Exit(130) from None
    counts = {k: sum(r.outcome == k for r in results) for k in ("imported", "skipped", "failed")}
    text = ", ".join(f"{n} {k}" for k, n in counts.items()) + f" (MLflow store {tracking_uri()})"
    _echo({"uri": tracking_uri(), **counts, "runs": [vars(r) for r in results]}, as_json, text)
    if counts["failed"]:
        _fail(f"{counts['failed']} run dirs not imported: their errors are above")


def video(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt."),
    episodes: int = typer.Option(3, min=1, help="Episodes per task (SGN, then EQA unless the run is SGN only)."),
    out: Path = typer.Option(Path("reports"), help="Folder for the GIFs."),
    seed: int = typer.Option(0, help="Seed of the first episode (episode i plays seed + i)."),
):
    """A captioned GIF per greedy episode: the sentence, each action, the outcome.

    Written as TABLE-RUN-TASK-sSEED.gif (named by the run's table and run)."""
    from emml.report.visualize import episode_gif, record_episode

    ((_, model, cfg),) = _models(checkpoint)
    _own_engines()
    out = _out(out)
    for task in cfg.env.played:
        for i in range(episodes):
            ep = record_episode(model, cfg.env, task, seed + i)
            path = episode_gif(ep, out / f"{cfg.table}-{checkpoint.parent.name}-{task}-s{seed + i}.gif")
            typer.echo(f"wrote {path} ('{ep.sentence}': {'success' if ep.success else 'failure'})")


def visualize_channels(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt."),
    compare: Path | None = typer.Option(None, help="A second checkpoint (e.g. the No-Aux run) for another column."),
    out: Path = typer.Option(Path("reports"), help="Folder for the PNG."),
    seed: int = typer.Option(0, help="Seed of the episode whose first frame is shown."),
):
    """The channel figure: per word, its aux label, each model's conv3 channel, and the frame.

    Written as channels-TABLE-RUN.png: named by the run's table and run (two tables may have runs of one name)."""
    from emml.report.index import figure_name
    from emml.report.visualize import channels_figure

    models = _models(checkpoint, *([compare] if compare else []))
    _own_engines()
    out = _out(out)
    path = out / figure_name("channels", models[0][2].table, checkpoint.parent.name)
    channels_figure([(label, m) for label, m, _ in models], models[0][2].env, path, seed=seed)
    typer.echo(f"wrote {path}")


def visualize_attention(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt."),
    task: Task = typer.Option("sgn", help="The episode's task."),
    out: Path = typer.Option(Path("reports"), help="Folder for the PNG."),
    seed: int = typer.Option(0, help="Seed of the episode."),
    rows: int = typer.Option(6, min=1, help="Steps shown, spread over the episode."),
):
    """The attention figure: one greedy episode, rows over time (frame, x_spat, x_Ans, action), x_sent on top.

    Written as attention-TASK-TABLE-RUN-sSEED.png (named by the run's table and run)."""
    from emml.report.index import figure_name
    from emml.report.visualize import attention_figure, record_episode
    from emml.tasks.language import TASKS, check_choice

    try:
        check_choice("task", task, TASKS)
    except ValueError as e:
        _fail(str(e))
    ((_, model, cfg),) = _models(checkpoint)
    _own_engines()
    out = _out(out)
    ep = record_episode(model, cfg.env, task, seed)
    path = out / figure_name(f"attention-{task}", cfg.table, checkpoint.parent.name, f"-s{seed}")
    attention_figure(ep, path, rows)
    typer.echo(f"wrote {path} ('{ep.sentence}': {'success' if ep.success else 'failure'} in {len(ep.frames)} steps)")


def visualize_house(
    out: Path = typer.Option(Path("reports"), help="Folder for the PNG."),
    seed: int = typer.Option(0, help="Seed of the furniture's colours."),
):
    """Three first-person views of the House with furniture in the episode's colours (Appendix C's example views)."""
    from emml.report.house_views import house_views

    _own_engines()
    path = house_views(_out(out) / "house-views.png", seed=seed)
    typer.echo(f"wrote {path}")
