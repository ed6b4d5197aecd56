"""Training curves from MLflow metric histories: training success per task vs frames (like the paper's Figures
7 and 8), with the greedy evaluation points."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from emml.config.profiles import Profile  # noqa: E402
from emml.eval.metrics import BY_NAME, DECLARED, train_of  # noqa: E402
from emml.report.aggregate import reference_row  # noqa: E402
from emml.report.savefig import PAGE_HEIGHT_INCHES, PAGE_INCHES, caption_path, frames_axis, save, wrap  # noqa: E402
from emml.runs.atomic import write_text  # noqa: E402
from emml.runs.diskspace import RERUN  # noqa: E402
from emml.runs.store import metric_history  # noqa: E402

TRAIN_KEYS = (("train/success_sgn", "SGN"), ("train/success_eqa", "EQA"))
"""The training-episode success curves (the paper's figures plot them); the table pages draw the greedy evaluation
of the tables' own metric instead (`curve_key`)."""
SERIES = (
    *((key, f"{task}, training episodes", train_of(task.lower()).colour, "-") for key, task in TRAIN_KEYS),
    *(
        (m.key, f"{m.label}, greedy eval", m.colour, "o" if m.train_column else "s")
        for m in sorted((m for m in DECLARED if m.periodic), key=lambda m: not m.train_column)
    ),
)
"""A run's curves (`plot_run`): its training episodes' success per task in the colour of the task's training split,
then every periodically evaluated metric as declared (emml/eval/metrics.py), the training splits first."""


def plot_run(run_id: str, path: Path, title: str) -> Path:
    fig, ax = plt.subplots(figsize=(PAGE_INCHES, 3.5), layout="constrained")
    for key, label, color, style in SERIES:
        hist = metric_history(run_id, key)
        if not hist:
            continue
        steps, values = zip(*hist)
        if style == "-":
            ax.plot(steps, values, style, color=color, label=label)
        else:
            ax.plot(steps, values, style, color=color, label=label, linestyle="--", alpha=0.8)
    sgn = train_of("sgn")
    ax.axhline(sgn.uniform, color="grey", lw=0.8, ls=":", label=f"SGN chance (1 of {round(1 / sgn.uniform)})")
    frames_axis(ax)
    ax.set_ylabel("accuracy")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(wrap(title, PAGE_INCHES - 0.2, plt.rcParams["axes.titlesize"]))
    ax.legend(loc="upper left")
    ax.grid(alpha=0.3)
    save(fig, path)
    plt.close(fig)
    return path


# --- a table's curves of its own metric (the paper's Figures 7, 8: Table 2; Figure 9: Table 3) -------------------

GRID_POINTS = 300
"""Curves are resampled on at most this many frame values before averaging seeds (keeps the bootstrap cheap)."""


def curve_key(metric: str) -> tuple[str, str]:
    """The metrics-mirror key of a table column's greedy evaluation and its label: eval/sgn_test for sgn_test; a
    transfer table's sgn_transfer (scored once, after training) draws its runs' training instructions."""
    declared = BY_NAME[metric]
    return declared.key, declared.curve


def _mean_band(curves: list[tuple[np.ndarray, np.ndarray]]):
    """Common frame grid (up to the shortest seed's end), the seed mean and a 95% percentile-bootstrap band
    (scipy.stats.bootstrap over seeds, per grid point; None with one seed)."""
    from scipy import stats

    end = min(x[-1] for x, _ in curves)
    start = max(x[0] for x, _ in curves)
    grid = np.linspace(start, end, GRID_POINTS) if end > start else np.array([end])
    ys = np.stack([np.interp(grid, x, y) for x, y in curves])
    mean = ys.mean(axis=0)
    if len(curves) < 2:
        return grid, mean, None
    res = stats.bootstrap(
        (ys,), np.mean, axis=0, method="percentile", n_resamples=2000, rng=np.random.default_rng(0), vectorized=True
    )
    low, high = res.confidence_interval
    flat = np.all(ys == ys[0], axis=0)  # identical seeds: a degenerate bootstrap; the band is the mean
    return grid, mean, (np.where(flat, mean, low), np.where(flat, mean, high))


def plot_table(
    name: str,
    profile: Profile | str,
    results_root: str | Path | None = None,
    out: str | Path | None = None,
    run_root: str | Path | None = None,
) -> tuple[list[Path], list[str]]:
    """Greedy accuracy vs frames for every row of table `name` under `profile`, on the table's own metrics (SGN and
    EQA test for Table 2): a panel per (metric, difficulty, aux) that has a curve (no empty panel), one line per row
    (mean over seeds, 95% bootstrap band), the paper's number for the row marked at the right edge, the task's chance
    dotted. The figure is at most `PAGE_INCHES` × `PAGE_HEIGHT_INCHES` (rows of panels lower when many); what it
    shows and the deviations from the paper of the runs drawn, read from their configs (emml/report/deviations.py),
    are its caption, written beside it (`caption_path`: the table's page prints it under the figure). Runs come
    from results/<name>/<profile>.csv (their run_id), curves from MLflow,
    else from the run dir's metrics.csv (under ``run_root``, default: the profile's); a run with neither is skipped
    with a note. When no run has a curve here, existing figures are kept rather than replaced by empty ones. Returns
    (paths, notes)."""
    import matplotlib.transforms as mtransforms
    from matplotlib.lines import Line2D

    from emml.report import deviations
    from emml.report.cells import AUX_LABELS, DIFFICULTY_LABELS, paper_numbers, table_results
    from emml.report.chance import task_ceiling
    from emml.report.plan import plan_report
    from emml.report.tables import reports_dir
    from emml.runs.records import points_or_none
    from emml.runs.rundir import METRICS, path_of

    plan = plan_report(name, profile, results_root, run_root)  # once: every run's config and name (issue 64)
    table, prof, run_root = plan.table, plan.profile, plan.run_root
    profile = prof.name
    out = reports_dir(prof, out)
    notes: list[str] = []
    if table.placeholder:
        return [], [f"{name} is a placeholder: no runs, no curves"]
    results = table_results(table, prof, plan.results_root)  # its own rows, and those it borrows (Table 3's DA)
    prior = task_ceiling()  # the task's blind ceiling, enumerated (emml/envs/ceiling.py), not a run's score
    run_ids = dict(zip(results["run_name"], results["run_id"]))
    paper = {(r.row, r.difficulty, r.aux, r.metric): r.value for r in paper_numbers(table.name).itertuples()}
    metrics = list(dict.fromkeys(table.metrics.values()))
    keys = list(dict.fromkeys(curve_key(m)[0] for m in metrics))
    cache: dict[str, dict] = {}
    drawn: dict = {}  # run name → PlannedRun of every run with a curve in the figure
    panels: dict[tuple, list] = {}  # (metric, difficulty, aux) → [(row index, row, curves)]
    for metric in metrics:
        key = curve_key(metric)[0]
        for difficulty in table.difficulties:
            for aux in table.aux:
                for k, row in enumerate(table.curve_rows()):
                    curves = []
                    cell = {id(r) for r in plan.cell_runs(row, difficulty, aux, metric)}
                    for run in plan.runs:
                        spec, rname = run.spec, run.name
                        if spec.row != row or spec.difficulty != difficulty or spec.aux != aux:
                            continue
                        if table.transfer is None and id(run) not in cell:
                            continue  # DA Single-Task: its SGN-only run draws SGN, its EQA-only run EQA
                        if rname not in run_ids:
                            continue
                        if rname not in cache:
                            cache[rname] = {kk: _history(run_ids[rname], kk) for kk in keys}
                            mirror: list | None = []
                            if not any(cache[rname].values()):  # another store's run: its run dir may be here
                                mirror = points_or_none(path_of(run_root, spec.table, rname) / METRICS)
                                cache[rname] = {kk: [(st, v) for st, x, v in mirror or [] if x == kk] for kk in keys}
                            if mirror is None:  # damaged: named once in a note with its line; this run only
                                notes.append(f"{rname}: no curve: its metrics.csv is damaged (a note names the line)")
                            elif not any(cache[rname].values()):
                                notes.append(
                                    f"{rname}: no curve (MLflow run {run_ids[rname]} not here, no run dir); skipped"
                                )
                        hist = sorted(dict(cache[rname][key] or []).items())
                        if hist:
                            steps, values = zip(*hist)
                            curves.append((np.asarray(steps, float), np.asarray(values, float)))
                            drawn.setdefault(rname, run)
                    if curves:
                        panels.setdefault((metric, difficulty, aux), []).append((k, row, curves))
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{name}-{profile}-curves.png", out / f"{name}-{profile}-curves.pdf"]
    if not panels:  # never an empty figure: keep what an earlier machine drew, or draw nothing
        kept = [p for p in paths if p.exists()]
        what = "kept the existing figures" if kept else "no figure written"
        return kept, notes + [f"no run of {name} [{profile}] has a curve here: {what}"]
    settings = list(dict.fromkeys((d, a) for (_, d, a) in panels))
    shown_metrics = list(dict.fromkeys(m for (m, _, _) in panels))
    rows = {r["run_name"]: r for r in results.to_dict("records")} if not results.empty else {}
    shown = [deviations.shown_run(run, run_root, rows.get(r)) for r, run in drawn.items()]
    fig = plt.figure(figsize=(PAGE_INCHES, figure_height(len(shown_metrics))), layout="constrained")
    grid = fig.add_gridspec(len(shown_metrics), len(settings))
    ref = reference_row(table)
    width = PAGE_INCHES / len(settings)
    legend: dict = {}
    for i, metric in enumerate(shown_metrics):
        for j, (difficulty, aux) in enumerate(settings):
            lines = panels.get((metric, difficulty, aux))
            if not lines:
                continue  # no run of this metric in this setting: no empty panel
            ax = fig.add_subplot(grid[i, j])
            edge = mtransforms.blended_transform_factory(ax.transAxes, ax.transData)
            for k, row, curves in lines:
                grid_x, mean, band = _mean_band(curves)
                color = f"C{k % 10}"
                main = row == ref  # the paper's model, drawn over the others
                ax.plot(
                    grid_x,
                    mean,
                    color=color,
                    marker="o" if len(grid_x) == 1 else None,
                    label=row,
                    lw=2.2 if main else 1.0,
                    zorder=3 if main else 2,
                )
                if band is not None:
                    ax.fill_between(grid_x, band[0], band[1], color=color, alpha=0.2, lw=0)
                value = paper.get((row, difficulty, aux, metric))
                if value not in (None, ""):
                    ax.plot([1.0], [float(value)], marker="<", ms=5, color=color, transform=edge, clip_on=False)
            line = prior.of(curve_key(metric)[0].removeprefix("eval/"), difficulty)  # the best blind score here
            ax.axhline(line, color="grey", lw=0.8, ls=":")
            label = curve_key(metric)[1]
            title = f"{label}: {DIFFICULTY_LABELS.get(difficulty, difficulty)}, {AUX_LABELS[aux]}"
            ax.set_title(wrap(title, width - 0.2, plt.rcParams["axes.titlesize"]))
            ax.set_ylim(-0.02, 1.02)
            frames_axis(ax)
            if j == 0:
                ax.set_ylabel("greedy accuracy")
            else:
                ax.tick_params(labelleft=False)
            for handle, text in zip(*ax.get_legend_handles_labels()):
                legend.setdefault(text, handle)
            legend.setdefault(f"blind ceiling {line:.2f}", Line2D([], [], color="grey", lw=0.8, ls=":"))
            if any(paper.get((row, difficulty, aux, metric)) for _, row, _ in lines):
                legend.setdefault("paper (its frames)", Line2D([], [], color="grey", marker="<", ls=""))
    longest = max(len(t) for t in legend)
    ncol = max(1, min(len(legend), int(PAGE_INCHES * 72 / (0.6 * plt.rcParams["legend.fontsize"] * longest + 30))))
    fig.legend(list(legend.values()), list(legend), loc="outside lower center", ncol=ncol)
    title = f"{name} [{profile}]: greedy accuracy (the table's metric), seed mean, 95% bootstrap band"
    fig.suptitle(wrap(title, PAGE_INCHES - 0.1, plt.rcParams["figure.titlesize"]))
    for p in paths:
        save(fig, p)
    plt.close(fig)
    runs = deviations.sentence(deviations.summarise(shown)) if shown else ""
    write_text(caption_path(paths[0]), caption(name, profile, runs) + "\n", then=RERUN)
    return paths, notes


def caption(name: str, profile: str, deviations: str) -> str:
    """The curves' caption (markdown): what the figure draws, and ``deviations``, those of the runs it draws (one
    paragraph, `emml.report.deviations.sentence`; empty: none read)."""
    protocol = "" if profile == "paper" else f" Profile '{profile}' is not the paper's protocol."
    text = (
        f"*Figure: {name} [{profile}], greedy accuracy (the table's metric, periodic evaluation) against frames: the "
        "seed mean and its 95% bootstrap band per row; the paper's number marked (◀) at the right edge; dotted: "
        f"chance, the best a model that sees no frame can score (enumerated from the task).{protocol}*"
    )
    return f"{text} **The runs drawn.** {deviations}" if deviations else text


PANEL_INCHES = 1.9
"""The height of a row of panels; the figure is `PAGE_INCHES` wide, each setting a column."""
CHROME_INCHES = 1.2
"""The figure's height beside its panels: the title above them, the legend under them."""


def figure_height(rows: int) -> float:
    """Inches: `rows` rows of panels `PANEL_INCHES` tall, lower where that would pass `PAGE_HEIGHT_INCHES`."""
    return CHROME_INCHES + rows * min(PANEL_INCHES, (PAGE_HEIGHT_INCHES - CHROME_INCHES) / max(rows, 1))


def _history(run_id: str, key: str) -> list[tuple[int, float]] | None:
    """The metric's history; [] when the run never logged it (a single-task run) or MLflow lacks the run, None when
    the store cannot be read for it."""
    try:
        return metric_history(str(run_id), key)
    except Exception:  # the run is not in this MLflow store (another machine's database, a fresh checkout)
        return None
