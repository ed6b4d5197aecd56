"""Training and scoring: `emml train`, `eval`, `rescore`, `transfer` and `demo`."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import NoReturn

import typer

from emml.cli.common import (
    _CONTROLS,
    JSON_HELP,
    QUIET_HELP,
    RESULTS_ROOT_HELP,
    RUN_ROOT_HELP,
    SEED_HELP,
    SET_HELP,
    Control,
    Difficulty,
    _check_checkpoint,
    _echo,
    _fail,
    _out,
    _own_engines,
    _parse_sets,
    _use_tcmalloc,
    device_option,
    model_option,
    profile_option,
)
from emml.runs.naming import run_name


def train(
    model: str = model_option(),
    difficulty: Difficulty = typer.Option("easy", help="Where it trains: Doom Easy, Doom Hard or the House."),
    aux: bool = typer.Option(False, "--aux/--no-aux", help="Train with the auxiliary task (§3.2)."),
    profile: str = profile_option(),
    seed: int = typer.Option(0, help="The run's seed (model init, episodes)."),
    table: str = typer.Option("adhoc", help="Table the run belongs to: its run dir folder and MLflow experiment."),
    device: str = device_option(),
    frames: int = typer.Option(0, help="Frames to train (0: the profile's)."),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    pack_seeds: str = typer.Option(
        "", help="Train these seeds in one process as one stacked model, e.g. 0,1,2 (each written as its own run)."
    ),
    run_root: str = typer.Option(None, help=RUN_ROOT_HELP),
    results_root: str = typer.Option(None, help=RESULTS_ROOT_HELP),
    quiet: bool = typer.Option(False, help=QUIET_HELP),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Train one run, or resume it.

    An interrupted run resumes from its checkpoint; a finished one is not trained again. With no option it trains
    Dual-Attention without aux on Doom Easy under the quick profile (1.5M frames), and says so first. With
    --pack-seeds, several seeds train in one process, each written as its own run."""
    from emml.config.profiles import profile_config
    from emml.rl.prepare import prepare

    overrides = _parse_sets(sets)
    if frames:
        overrides["frames"] = frames
    overrides.update({k: v for k, v in (("run_root", run_root), ("results_root", results_root)) if v is not None})
    try:
        seeds = [int(s) for s in pack_seeds.split(",")] if pack_seeds else [seed]
    except ValueError:
        _fail(f"--pack-seeds {pack_seeds!r}: allowed values are integers separated by commas, e.g. 0,1,2")
    try:
        cfgs = [
            profile_config(profile, difficulty, overrides, model=model, aux=aux, seed=s, table=table, device=device)
            for s in seeds
        ]
        if pack_seeds:
            from emml.rl.packed_trainer import check_packable

            check_packable(cfgs)
        # the values, the model registry and the machine, then the store, the run and results folders, the results
        # CSV: before any engine or run (emml/rl/prepare.py)
        cfg = prepare(*cfgs)[0]
    except ValueError as e:
        _fail(str(e))
    _use_tcmalloc()
    if cfg.num_updates * cfg.frames_per_update != cfg.frames and not (quiet or as_json):  # after the re-exec: once
        typer.echo(
            f"note: frames={cfg.frames:,} rounded up to whole updates of num_envs × num_steps = "
            f"{cfg.frames_per_update:,}: {cfg.num_updates * cfg.frames_per_update:,} frames",
            err=True,
        )
    _own_engines(defer=False)
    from emml.rl.trainer import train as run
    from emml.runs.checkpoint import CheckpointError
    from emml.runs.diskspace import NoSpaceError
    from emml.runs.records import RecordError
    from emml.runs.rundir import ConfigMismatch, RunDirError
    from emml.runs.runlock import RunLocked

    if pack_seeds:
        from emml.rl.packed_trainer import train_packed

        try:
            results = train_packed(cfgs, quiet=quiet or as_json)
        except (CheckpointError, ConfigMismatch, RunLocked, ValueError, NoSpaceError) as e:
            _fail(str(e))
        except (KeyboardInterrupt, SystemExit) as e:
            _stopped(e, len(cfgs))
        data = [{"run_dir": str(r.run_dir), "run_id": r.run_id, "frames": r.frames, **r.metrics} for r in results]
        text = [
            f"{run_name(c)} after {r.frames:,} frames: " + ", ".join(f"{k} {v:.3f}" for k, v in r.metrics.items())
            for c, r in zip(cfgs, results)
        ]
        _echo(data, as_json, "\n".join(text))
        return
    try:  # raised before any engine starts or anything is written, but a full disk (the run then ends FAILED)
        result = run(cfg, quiet=quiet or as_json)
    except (CheckpointError, ConfigMismatch, RunLocked, NoSpaceError, RunDirError, RecordError) as e:
        _fail(str(e))
    except (KeyboardInterrupt, SystemExit) as e:
        _stopped(e, 1)
    data = {
        "run_dir": str(result.run_dir),
        "run_id": result.run_id,
        "frames": result.frames,
        "skipped": result.skipped,
        "resumed": result.resumed,
        **result.metrics,
    }
    _echo(
        data,
        as_json,
        ("already finished: " if result.skipped else "")
        + f"{run_name(cfg)} after {result.frames:,} frames: "
        + ", ".join(f"{k} {v:.3f}" for k, v in result.metrics.items())
        + f"\n  run dir {result.run_dir}",
    )


def _stopped(e: BaseException, runs: int) -> NoReturn:
    """A training stopped by Ctrl-C or SIGTERM (its run saved and ended KILLED by the trainer) ends as `emml run` and
    `emml campaign` do (issue 65): their one stopped line, the resuming command being this same one, and exit 130.
    Any other exit goes on as it was."""
    from emml.experiments.launch import stop_cause, stop_line

    cause = stop_cause(e)
    if cause is None:
        raise e
    typer.echo(stop_line(cause, 0, runs, shlex.join(["emml", *sys.argv[1:]])))
    raise typer.Exit(130) from None


def eval_checkpoint(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt."),
    episodes: int = typer.Option(100, min=1, help="Episodes per (task, split)."),
    seed: int = typer.Option(10_000, help=SEED_HELP),
    control: Control | None = typer.Option(None, help="Play under a diagnostic control: " + _CONTROLS + "."),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Greedy accuracy of a checkpoint on SGN and EQA, train and test.

    Reproducible: episode i of each (task, split) plays seed + i."""
    from emml.eval.evaluate import evaluate_checkpoint

    _check_checkpoint(checkpoint)
    _own_engines()
    if not as_json:
        typer.echo(f"evaluating {checkpoint}: {episodes} greedy episodes per task and split…", err=True)
    try:
        result = evaluate_checkpoint(checkpoint, episodes, seed, control=control)
    except ValueError as e:  # a control the model cannot take
        _fail(str(e))
    _echo(result, as_json, ", ".join(f"{k} {v:.3f}" for k, v in result.items()))


def rescore_runs(
    runs: list[Path] = typer.Argument(..., help="Finished run dirs (or their checkpoint.pt)."),
    episodes: int = typer.Option(0, min=0, help="Episodes per (task, split); 0: the run's final_eval_episodes."),
    seed: int = typer.Option(10_000, help="First episode seed (the trainer's evaluations use 10,000)."),
    record: bool = typer.Option(True, "--record/--no-record", help="Also upsert the run's results-table row."),
    force: bool = typer.Option(False, "--force", help="Play again a run already scored with this protocol."),
    results_root: str = typer.Option(
        None, help="Folder of the results CSVs whose rows are rewritten (default: the run's, from its checkpoint)."
    ),
    device: str = device_option(),
    questions: bool = typer.Option(
        False,
        "--questions",
        help="Only count EQA per question: replay the row's final-evaluation EQA episodes (its eval_seed and "
        "eval_episodes), check they reproduce its eqa_train/eqa_test exactly, and write the counts to results.json "
        "and <profile>-questions.csv; the results row is not changed (--episodes, --seed and --record are unused).",
    ),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Score finished runs again with the final-evaluation protocol.

    Each run's results.json and results row are rewritten with the new score; its training provenance is kept,
    and scored_sha, eval_episodes and eval_seed are recorded. A run already scored so is only re-recorded.
    With --questions, EQA's successes per question are counted instead, the score left as it is."""
    from emml.config.schema import TrainConfig
    from emml.eval.rescore import NoProvenance, NotFinished, check_finished, rescore, training_record
    from emml.runs.checkpoint import load_checkpoint
    from emml.runs.runlock import RunLocked

    for run in runs:  # every run checked before any is played
        rdir = run if run.is_dir() else run.parent
        _check_checkpoint(rdir / "checkpoint.pt")
        ckpt = load_checkpoint(rdir / "checkpoint.pt")
        cfg = TrainConfig.from_dict(ckpt["config"])
        if results_root is not None:
            cfg.results_root = results_root
        try:
            check_finished(rdir, ckpt, cfg)
            training_record(rdir, ckpt, cfg)
        except (NotFinished, NoProvenance) as e:
            _fail(str(e))
    _own_engines()
    if questions:
        _rescore_questions(runs, results_root, device, force, as_json)
        return
    data, lines = [], []
    for run in runs:
        if not as_json:
            typer.echo(f"re-scoring {run}…", err=True)
        try:
            r = rescore(run, episodes, seed, record=record, force=force, results_root=results_root, device=device)
        except RunLocked as e:  # being trained: its score is not final
            _fail(str(e))
        data.append({"run_dir": str(r.run_dir), "before": r.before, "after": r.after, "played": r.played})
        data[-1]["csv"] = str(r.csv) if r.csv else None
        keys = [k for k in r.after if k not in ("eval_episodes", "eval_seed")]
        scores = ", ".join(f"{k} {_score(r.before.get(k))} -> {r.after[k]:.3f}" for k in keys)
        protocol = f"{r.before['eval_episodes']} -> {r.after['eval_episodes']} episodes, seed {r.after['eval_seed']}"
        lines.append(f"{r.run_dir.name}: {scores} ({protocol})" + ("" if r.played else " [already scored]"))
        lines.append(f"  wrote {r.run_dir / 'results.json'}" + (f" and its row in {r.csv}" if r.csv else ""))
    _echo(data, as_json, "\n".join(lines))


def _score(value) -> str:
    return "-" if value is None else f"{value:.3f}"


def _rescore_questions(runs: list[Path], results_root: str | None, device: str, force: bool, as_json: bool) -> None:
    """`emml rescore --questions`: each run in turn (emml.eval.rescore.rescore_questions); a run whose replay does not
    reproduce its row is named and skipped (nothing written for it), and the command then exits 1."""
    from emml.eval.rescore import NotReproduced, rescore_questions
    from emml.runs.runlock import RunLocked

    data, failed = [], []
    for run in runs:
        if not as_json:
            typer.echo(f"counting EQA per question of {run}…", err=True)
        try:
            r = rescore_questions(run, results_root=results_root, device=device, force=force)
        except NotReproduced as e:
            typer.secho(f"error: {e}", fg=typer.colors.RED, err=True)
            failed.append(str(run))
            continue
        except RunLocked as e:  # being trained: its score is not final
            _fail(str(e))
        totals = {
            s: (sum(c["successes"] for c in q.values()), sum(c["episodes"] for c in q.values()))
            for s, q in r.questions.items()
        }
        item = {"run_dir": str(r.run_dir), "played": r.played, "seconds": round(r.seconds, 1), "csv": str(r.csv)}
        data.append({**item, "questions": r.questions})
        if not as_json:
            sums = ", ".join(f"{s} {k}/{n} = {k / n:.3f}" for s, (k, n) in totals.items())
            how = f"replayed in {r.seconds:.0f} s" if r.played else "already counted"
            typer.echo(f"{r.run_name}: {sums} over {sum(map(len, r.questions.values()))} questions ({how}); {r.csv}")
    if as_json:
        _echo({"runs": data, "not_reproduced": failed}, True, "")
    if failed:
        raise typer.Exit(1)


def transfer(
    checkpoint: Path = typer.Argument(
        ..., help="A checkpoint of an SGN Dual-Attention run that does not know the words."
    ),
    words: str = typer.Option("red,pillar", help="New words, comma-separated, in channel order."),
    episodes: int = typer.Option(100, min=1, help="Greedy episodes per test instruction."),
    detector: str = typer.Option("labels", help="Detector kind: labels (the engine's label buffer)."),
    seed: int = typer.Option(10_000, help=SEED_HELP),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Table 4 on one checkpoint: new words without fine-tuning.

    Detectors for the new words are appended (§5.4) and every SGN test instruction holding one is scored; rows as
    in reproduce/table4.toml."""
    from emml.eval.transfer import transfer_checkpoint
    from emml.experiments.tables import load_table

    _check_checkpoint(checkpoint)
    _own_engines()
    new_words = tuple(w.strip() for w in words.split(",") if w.strip())
    try:
        scores = transfer_checkpoint(checkpoint, new_words, episodes=episodes, seed=seed, detector=detector)
    except ValueError as e:
        _fail(str(e))
    table = load_table("table4")
    rows = {}
    if new_words == table.transfer.words:  # the paper's words: its rows (and ours below them)
        rows = {r.label: sum(scores[x] for x in r.instructions) / len(r.instructions) for r in table.rows}
    width = max(map(len, [*scores, *rows]))
    text = "\n".join(
        [f"{k:<{width}}  {v:.2f}" for k, v in rows.items()]
        + (["", "per instruction:"] if rows else [])
        + [f"{k:<{width}}  {v:.2f}" for k, v in scores.items()]
    )
    _echo({"instructions": scores, "rows": rows, "episodes": episodes, "words": list(new_words)}, as_json, text)


def demo(
    out: Path = typer.Option(Path("reports"), help="Folder of the report."),
    profile: str = profile_option("demo", help="Profile of the demo run (reproduce/profiles.toml)."),
    run_root: str = typer.Option(None, help=RUN_ROOT_HELP),
    results_root: str = typer.Option(None, help=RESULTS_ROOT_HELP),
):
    """A short training with its report: the demo of `make demo`.

    Dual-Attention with aux on Doom Easy instructions (SGN), evaluated and logged to MLflow, with a report
    (accuracies, training curve, diagnostics) in reports/."""
    from emml.config.profiles import profile_config

    # SGN only: within the demo's minutes the agent leaves chance on instructions (both tasks need more frames)
    over = {"env.tasks": "sgn"}
    over.update({k: v for k, v in (("run_root", run_root), ("results_root", results_root)) if v is not None})
    try:
        cfg = profile_config(profile, "easy", over, model="dual_attention", aux=True, seed=0, table="demo")
        from emml.rl.prepare import prepare

        (cfg,) = prepare(cfg)  # before any engine or MLflow run
    except ValueError as e:
        _fail(str(e))
    _use_tcmalloc()
    _own_engines(defer=False)
    from emml.report.demo import write_demo_report
    from emml.rl.trainer import train as run

    result = run(cfg)
    for path in write_demo_report(cfg, result, _out(out)):
        typer.echo(f"wrote {path}")
