"""`emml reports` / `make reports`: every table, curve and figure for the profiles that have results, and
reports/index.md linking them with their profile and frames."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from emml.config.paths import project_path, project_root
from emml.config.profiles import Profile, resolve_profile
from emml.eval.metrics import TRAIN_COLUMNS
from emml.experiments.plan import PlannedRun
from emml.runs.atomic import write_text
from emml.runs.diskspace import RERUN
from emml.runs.rundir import CHECKPOINT, RunDirError, finished_run

READING_ORDER = ("quick", "paper")
"""The profiles a reader should read first, in this order; any other (demo…) follows."""


def profiles_with_results(results_root: str | Path = "results") -> dict[str, list[str]]:
    """Profile → the tables that have a results CSV for it (demo rows are the demo's own), quick first, then
    paper, then the others; never a profile whose numbers are not results (smoke: `emml.config.profiles.is_scratch`),
    even if a CSV of it lies here. The experiments beyond the paper's tables (reproduce/experiments/<name>.toml, e.g.
    issue 34's eqa_readout) with results are listed after the paper's tables, by name, loadable by it."""
    from emml.config.profiles import is_scratch, load_profiles
    from emml.experiments.table_files import EXPERIMENTS_DIR, list_experiments, list_tables, own_table
    from emml.experiments.tables import load_table

    known = load_profiles()
    experiments = set(list_experiments())
    out: dict[str, list[str]] = {}
    for csv in sorted(project_path(results_root).glob("*/*.csv")):
        name = csv.parent.name
        if csv.stem not in known or is_scratch(csv.stem) or not (name.startswith("table") or name in experiments):
            continue
        if name in experiments:
            own_table(EXPERIMENTS_DIR / f"{name}.toml")  # `load_table(name)` finds it from here on
        out.setdefault(csv.stem, []).append(name)
    for profile, tables in out.items():  # a table whose only runs so far are another's (Table 3's DA Multi-Task)
        for name in list_tables():
            table = load_table(name)
            borrowed = {row.from_table for row in table.rows if row.from_table}
            if name in tables or not borrowed & set(tables):
                continue
            if _has_runs(table, resolve_profile(profile), results_root):
                tables.append(name)
        tables.sort(key=lambda t: (t in experiments, t))
    rank = {p: i for i, p in enumerate(READING_ORDER)}
    return dict(sorted(out.items(), key=lambda kv: (rank.get(kv[0], len(rank)), kv[0])))


def _has_runs(table, profile: Profile, results_root: str | Path) -> bool:
    """Whether any run the table declares under ``profile`` has a results row (its own or a borrowed table's)."""
    from emml.report.cells import table_results
    from emml.report.plan import plan_report

    df = table_results(table, profile, results_root)
    return not df.empty and bool(df["run_name"].isin(plan_report(table, profile, results_root).names).any())


def best_run(plan, model: str = "dual_attention", aux: bool = True) -> PlannedRun | None:
    """The planned run of ``model`` (``plan``: a table's report plan, emml/report/plan.py) with the highest mean
    training accuracy in the table's results CSV that has its checkpoint here; None if there is none (results
    committed without their run dirs)."""
    from emml.runs.results import read_results

    df = read_results(project_path(plan.results_root) / plan.table.name / f"{plan.profile.name}.csv")
    if df.empty:
        return None
    rows = df[(df["model"] == model) & (df["aux"] == aux)].copy()
    train_cols = [c for c in TRAIN_COLUMNS if c in rows]
    rows["score"] = rows[train_cols].mean(axis=1)
    planned = plan.by_name()
    for name in rows.sort_values("score", ascending=False)["run_name"]:
        run = planned.get(name)
        if run is not None and (run.directory / CHECKPOINT).exists():
            return run
    return None


def finished_no_aux(plan, run: PlannedRun) -> Path | None:
    """The checkpoint of the No-Aux run ``plan`` declares beside ``run`` (`ReportPlan.no_aux_of`: its
    `noaux_overrides` included, issue 48's warm-up) when that run has finished (emml.runs.rundir.finished_run), else
    None: an interrupted run's checkpoint is not a result, and the figures show results only."""
    other = plan.no_aux_of(run)
    return other.directory / CHECKPOINT if other is not None and finished_run(other.directory) else None


def figure_name(kind: str, table: str, run: str, suffix: str = "", ext: str = "png") -> str:
    """A run's figure's file name, named by its table and its run (issue 60: Table 3 and Table 4 both have a run
    `dual_attention-easy-aux-sgnonly-s0-quick`, and their figures named by run alone overwrote one another):
    ``channels-table3-<run>.png``, ``attention-sgn-table3-<run>-s0.png`` (``kind`` 'attention-sgn', ``suffix``
    '-s0')."""
    return f"{kind}-{table}-{run}{suffix}.{ext}"


def figures(
    checkpoint: Path,
    out: Path,
    compare: Path | None = None,
    seeds: tuple[int, ...] = (0, 1),
    table: str | None = None,
) -> list[Path]:
    """The channel figure (beside ``compare``, the No-Aux run, when given) and SGN/EQA attention figures, named by
    the run's table (``table``, else its config's) and its run (`figure_name`)."""
    from emml.report.visualize import attention_figure, channels_figure, record_episode
    from emml.runs.rundir import load_model

    model, cfg = load_model(checkpoint)
    name = checkpoint.parent.name
    table = table or cfg.table
    paths = []
    models = [("aux" if cfg.aux else "no aux", model)]
    if compare is not None:
        other, other_cfg = load_model(compare)
        models.append(("aux" if other_cfg.aux else "no aux", other))
    path = out / figure_name("channels", table, name)
    channels_figure(models, cfg.env, path)
    paths.append(path)
    for task in cfg.env.played:
        for seed in seeds:
            ep = record_episode(model, cfg.env, task, seed)
            path = out / figure_name(f"attention-{task}", table, name, f"-s{seed}")
            attention_figure(ep, path)
            paths.append(path)
    return paths


def claims_lines(profiles: dict, out: Path, results_root: str | Path, run_root: str | Path = "runs") -> list[str]:
    """Write each profile's claims page (emml/report/claims.py) and return the index's lead: a link per profile with
    its status counts."""
    from emml.experiments.claims import load_claims
    from emml.experiments.tables import load_table
    from emml.report.claims import campaign_costs, write_claims
    from emml.report.claims_page import counts

    costs = campaign_costs() if profiles else {}
    inferred = sum(c.inferred for c in load_claims().values())
    lines = []
    for profile in profiles:
        pages = [t for t in profiles[profile] if not load_table(t).placeholder]  # the table pages written beside
        path, decisions = write_claims(profile, out, results_root, costs, run_root, pages)
        summary = ", ".join(f"{n} {status}" for status, n in counts(decisions).items() if n)
        apart = sum(d.apart for d in decisions)  # not among the counts: the paper's own table fails their rule
        summary += f"; {apart} shown apart (the paper's table does not support its text)" if apart else ""
        lines += [
            f"**Claims ({profile})**: [{path.name}]({path.name}), {len(decisions)} claims ({inferred} of them "
            f"inferred from the paper's tables, not stated), each also decided on the paper's own tables: {summary}.",
            "",
        ]
    return lines


def write_reports(
    out: str | Path | None = None,
    results_root: str | Path = "results",
    run_root: str | Path = "runs",
    log: Callable[[str], None] = print,
) -> Path:
    """Regenerate every table and curve per profile with results, the figures of each profile's best
    Dual-Attention checkpoint (when its run dir is here), and reports/index.md. Returns the index path."""
    from emml.experiments.tables import load_table
    from emml.runs.checkpoint import CheckpointError  # torch: imported when reports are written, not with the module
    from emml.runs.records import RecordError
    from emml.runs.results import ResultsError

    out = Path(out) if out is not None else project_root() / "reports"
    out.mkdir(parents=True, exist_ok=True)
    lines = ["# Reports", "", "Regenerated by `make reports` (`emml reports`) from `results/` and the run dirs here."]
    lines += [
        "",
        "Read the `quick` profile first (the paper's protocol at reduced frames and input size), then `paper` (the "
        "paper's protocol) when it has runs; every table states the deviations from the paper of the runs it shows, "
        "read from their configs. Smoke runs (512 frames) are not results and are never listed.",
        "",
    ]
    lines[2:2] = claims_lines(
        profiles_with_results(results_root), out, results_root, run_root
    )  # the page leads with them
    drawn: set[tuple[str, str]] = set()  # the best runs (table, run) whose figures are drawn: each once
    for profile, tables in profiles_with_results(results_root).items():
        lines += [f"## Profile `{profile}`", ""]
        prof = resolve_profile(profile)  # once per profile: every table, curve and figure below reads it
        for table in tables:
            if load_table(table).placeholder:
                continue
            try:
                lines += _table_lines(table, prof, out, results_root, run_root, drawn, log)
            except (RunDirError, CheckpointError, RecordError, ResultsError) as e:  # one bad file: named; on
                log(f"{table} [{profile}]: not reported: {e}")
                lines.append(f"- **{table}**: not reported here: {e}")
        lines.append("")
    demo = sorted(out.glob("*-demo.md"))
    if demo:
        lines += ["## `make demo`", ""] + [f"- [{p.name}]({p.name})" for p in demo] + [""]
    index = out / "index.md"
    write_text(index, "\n".join(lines), then=RERUN)  # last, whole or not at all: it links only files written
    return index


def _table_lines(
    table: str, prof: Profile, out: Path, results_root, run_root, drawn: set[tuple[str, str]], log
) -> list[str]:
    """Write one table's report, curves and best run's figures; returns its lines of the index. A run dir whose
    files cannot be read is named and its figures left out, never the table's report."""
    import matplotlib.pyplot as plt

    from emml.report.cells import table_results
    from emml.report.curves import plot_table
    from emml.report.plan import plan_report
    from emml.report.tables import report_table
    from emml.runs.checkpoint import CheckpointError

    lines: list[str] = []
    profile = prof.name
    plan = plan_report(table, prof, results_root, run_root)
    df = table_results(plan.table, prof, results_root)
    df = df[df["run_name"].isin(plan.names)] if not df.empty else df
    frames = sorted(set(df["frames"])) if "frames" in df else []
    curve_paths, notes = plot_table(table, prof, results_root, out, run_root)  # first: the page embeds it
    plt.close("all")
    data = report_table(table, prof, results_root, out, run_root)
    plt.close("all")
    paths = [Path(p) for p in data["paths"]] + [Path(p) for p in curve_paths]
    runs = f"{len(df)} run{'s' if len(df) != 1 else ''}, frames {', '.join(f'{f:,}' for f in frames)}"
    lines.append(f"- **{table}** ({runs}): " + ", ".join(f"[{p.name}]({p.name})" for p in paths))
    missing = [n for n in notes if ": no curve (" in n]
    if missing:
        lines.append(
            f"  - note: {len(missing)} of {len(df)} runs have no curve here (their MLflow runs and "
            "run dirs are on the machine that trained them)"
        )
    lines += [f"  - note: {n}" for n in notes if n not in missing]
    log(f"{table} [{profile}]: {len(paths)} files")
    best = best_run(plan)
    if best is not None and (table, best.name) not in drawn:
        name = best.name
        drawn.add((table, name))
        try:
            figs = figures(best.directory / CHECKPOINT, out, finished_no_aux(plan, best), table=table)
        except (RunDirError, CheckpointError) as e:
            log(f"{table} [{profile}]: no figures of {name}: {e}")
            return [*lines, f"  - note: no figures of `{name}` here: {e}"]
        finally:
            plt.close("all")
        lines.append(
            f"  - figures of the best Dual-Attention run `{name}`: " + ", ".join(f"[{p.name}]({p.name})" for p in figs)
        )
    return lines
