"""Training curves: a run's training success per task vs frames from its MLflow histories (`plot_run`, like the
paper's Figures 7 and 8, with the greedy evaluation points), and a table's greedy evaluation curves (`plot_table`),
each run's curve read as every page reads it (emml/runs/curve.py), all fetched before anything is drawn."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.transforms as mtransforms  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from emml.config.profiles import Profile  # noqa: E402
from emml.eval.metrics import BY_NAME, DECLARED, train_of  # noqa: E402
from emml.report.aggregate import reference_row  # noqa: E402
from emml.report.cells import AUX_LABELS, DIFFICULTY_LABELS, paper_numbers, table_results  # noqa: E402
from emml.report.savefig import PAGE_HEIGHT_INCHES, PAGE_INCHES, caption_path, frames_axis, save, wrap  # noqa: E402
from emml.runs.atomic import write_text  # noqa: E402
from emml.runs.curve import RunCurve, read_curve  # noqa: E402
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


Panel = tuple[str, str, bool]
"""A panel of a table's curves figure: (metric, difficulty, aux)."""


@dataclass
class Line:
    """One row's line in a panel: its index among the table's rows (its colour), its label, its seeds' curves."""

    index: int
    row: str
    curves: list[tuple[np.ndarray, np.ndarray]]


@dataclass
class TableCurves:
    """What a table's curves figure draws, every curve fetched before anything is drawn (`table_curves`)."""

    read: dict[str, RunCurve] = field(default_factory=dict)
    """Run name → its curve as every page reads it (emml/runs/curve.py), for each run a panel could draw."""
    panels: dict[Panel, list[Line]] = field(default_factory=dict)
    """Each panel that has a curve, in the figure's order, with its rows' lines (no empty panel, no empty line)."""
    drawn: dict = field(default_factory=dict)
    """Run name → planned run, of every run with a curve in the figure, in the order first drawn."""
    notes: list[str] = field(default_factory=list)
    """A run that has no curve here, and why."""


def panel_runs(plan, run_ids: dict) -> dict[Panel, list[tuple[int, str, list]]]:
    """Per panel of the table (each metric, difficulty, aux) and per row (its index and label), the planned runs whose
    curve of the metric it draws: those of the row's cell (DA Single-Task: its SGN-only run draws SGN, its EQA-only
    run EQA; a transfer table: its training setting's runs, for every metric) with a results row (``run_ids``)."""
    table = plan.table
    out: dict[Panel, list[tuple[int, str, list]]] = {}
    for metric in dict.fromkeys(table.metrics.values()):
        for difficulty in table.difficulties:
            for aux in table.aux:
                out[(metric, difficulty, aux)] = [
                    (k, row, [r for r in _row_runs(plan, row, difficulty, aux, metric) if r.name in run_ids])
                    for k, row in enumerate(table.curve_rows())
                ]
    return out


def _row_runs(plan, row: str, difficulty: str, aux: bool, metric: str) -> list:
    if plan.table.transfer is None:
        return plan.cell_runs(row, difficulty, aux, metric)
    return [r for r in plan.runs if (r.spec.row, r.spec.difficulty, r.spec.aux) == (row, difficulty, aux)]


def fetch(candidates: dict[Panel, list[tuple[int, str, list]]], run_ids: dict) -> tuple[dict[str, RunCurve], list]:
    """Each candidate run's curve of the table's keys, read once (`emml.runs.curve.read_curve`: its run dir's
    metrics.csv, else the MLflow run of its results row), and a note for each run that has none."""
    keys = list(dict.fromkeys(curve_key(metric)[0] for (metric, _, _) in candidates))
    read: dict[str, RunCurve] = {}
    notes = []
    for lines in candidates.values():
        for run in (run for _, _, runs in lines for run in runs if run.name not in read):
            read[run.name] = curve = read_curve(run.directory, keys, run_ids[run.name])
            if curve.damaged:  # named once in a note with its line; this run only
                notes.append(f"{run.name}: no curve: its metrics.csv is damaged (a note names the line)")
            elif not curve.found:
                notes.append(f"{run.name}: no curve (MLflow run {run_ids[run.name]} not here, no run dir); skipped")
    return read, notes


def table_curves(plan, results) -> TableCurves:
    """The curves of table ``plan`` (its report plan) that its figure draws: its runs are those of ``results`` (the
    rows of its results and those it borrows, with their MLflow run ids), every curve fetched first (`fetch`)."""
    run_ids = {} if results.empty else dict(zip(results["run_name"], results["run_id"]))
    candidates = panel_runs(plan, run_ids)
    read, notes = fetch(candidates, run_ids)
    out = TableCurves(read, notes=notes)
    for panel, rows in candidates.items():
        key = curve_key(panel[0])[0]
        for k, row, runs in rows:
            with_curve = [r for r in runs if read[r.name].of(key)]
            out.drawn.update({r.name: r for r in with_curve if r.name not in out.drawn})
            if with_curve:
                line = Line(k, row, [_arrays(read[r.name].of(key)) for r in with_curve])
                out.panels.setdefault(panel, []).append(line)
    return out


def _arrays(points: list[tuple[int, float]]) -> tuple[np.ndarray, np.ndarray]:
    steps, values = zip(*points)
    return np.asarray(steps, float), np.asarray(values, float)


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
    from results/<name>/<profile>.csv (their run_id), their curves as every page reads them (`table_curves`:
    emml/runs/curve.py, the run dir's metrics.csv under ``run_root``, default the profile's, else the MLflow run); a
    run with neither is skipped with a note. When no run has a curve here, existing figures are kept rather than
    replaced by empty ones. Returns (paths, notes)."""
    from emml.report import deviations
    from emml.report.plan import plan_report
    from emml.report.tables import reports_dir

    plan = plan_report(name, profile, results_root, run_root)  # once: every run's config and name
    profile = plan.profile.name
    out = reports_dir(plan.profile, out)
    if plan.table.placeholder:
        return [], [f"{name} is a placeholder: no runs, no curves"]
    results = table_results(plan.table, plan.profile, plan.results_root)  # its own rows, and those it borrows
    fetched = table_curves(plan, results)  # every curve read before anything is drawn
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{name}-{profile}-curves.png", out / f"{name}-{profile}-curves.pdf"]
    if not fetched.panels:  # never an empty figure: keep what an earlier machine drew, or draw nothing
        kept = [p for p in paths if p.exists()]
        what = "kept the existing figures" if kept else "no figure written"
        return kept, fetched.notes + [f"no run of {name} [{profile}] has a curve here: {what}"]
    rows = {r["run_name"]: r for r in results.to_dict("records")} if not results.empty else {}
    shown = [deviations.shown_run(run, plan.run_root, rows.get(r)) for r, run in fetched.drawn.items()]
    fig = _figure(name, profile, plan.table, fetched.panels)
    for p in paths:
        save(fig, p)
    plt.close(fig)
    runs = deviations.sentence(deviations.summarise(shown)) if shown else ""
    write_text(caption_path(paths[0]), caption(name, profile, runs) + "\n", then=RERUN)
    return paths, fetched.notes


def _figure(name: str, profile: str, table, panels: dict[Panel, list[Line]]):
    """The figure: a row of panels per metric shown, a column per setting (difficulty, aux) shown; one legend under
    them all."""
    from emml.report.chance import task_ceiling

    paper = {(r.row, r.difficulty, r.aux, r.metric): r.value for r in paper_numbers(table.name).itertuples()}
    prior = task_ceiling()  # the task's blind ceiling, enumerated (emml/envs/ceiling.py), not a run's score
    settings = list(dict.fromkeys((d, a) for (_, d, a) in panels))
    shown_metrics = list(dict.fromkeys(m for (m, _, _) in panels))
    fig = plt.figure(figsize=(PAGE_INCHES, figure_height(len(shown_metrics))), layout="constrained")
    grid = fig.add_gridspec(len(shown_metrics), len(settings))
    legend: dict = {}
    for i, metric in enumerate(shown_metrics):
        for j, (difficulty, aux) in enumerate(settings):
            lines = panels.get((metric, difficulty, aux))
            if lines:  # no run of this metric in this setting: no empty panel
                ax = fig.add_subplot(grid[i, j])
                _panel(ax, (metric, difficulty, aux), lines, paper, reference_row(table))
                _mark(ax, (metric, difficulty, aux), lines, paper, prior, PAGE_INCHES / len(settings), j == 0, legend)
    longest = max(len(t) for t in legend)
    ncol = max(1, min(len(legend), int(PAGE_INCHES * 72 / (0.6 * plt.rcParams["legend.fontsize"] * longest + 30))))
    fig.legend(list(legend.values()), list(legend), loc="outside lower center", ncol=ncol)
    title = f"{name} [{profile}]: greedy accuracy (the table's metric), seed mean, 95% bootstrap band"
    fig.suptitle(wrap(title, PAGE_INCHES - 0.1, plt.rcParams["figure.titlesize"]))
    return fig


def _panel(ax, panel: Panel, lines: list[Line], paper: dict, ref: str) -> None:
    """A panel's lines: each row's seed mean and band, the reference row (the paper's model) over the others, the
    paper's number of the row marked at the right edge."""
    metric, difficulty, aux = panel
    edge = mtransforms.blended_transform_factory(ax.transAxes, ax.transData)
    for line in lines:
        grid_x, mean, band = _mean_band(line.curves)
        color = f"C{line.index % 10}"
        main = line.row == ref
        ax.plot(
            grid_x,
            mean,
            color=color,
            marker="o" if len(grid_x) == 1 else None,
            label=line.row,
            lw=2.2 if main else 1.0,
            zorder=3 if main else 2,
        )
        if band is not None:
            ax.fill_between(grid_x, band[0], band[1], color=color, alpha=0.2, lw=0)
        value = paper.get((line.row, difficulty, aux, metric))
        if value not in (None, ""):
            ax.plot([1.0], [float(value)], marker="<", ms=5, color=color, transform=edge, clip_on=False)


def _mark(ax, panel: Panel, lines: list[Line], paper: dict, prior, width: float, first: bool, legend: dict) -> None:
    """A panel's chance line, title and axes (the y labels on the ``first`` column only), and its entries of the
    figure's legend."""
    metric, difficulty, aux = panel
    key, label = curve_key(metric)
    chance = prior.of(key.removeprefix("eval/"), difficulty)  # the best blind score here
    ax.axhline(chance, color="grey", lw=0.8, ls=":")
    title = f"{label}: {DIFFICULTY_LABELS.get(difficulty, difficulty)}, {AUX_LABELS[aux]}"
    ax.set_title(wrap(title, width - 0.2, plt.rcParams["axes.titlesize"]))
    ax.set_ylim(-0.02, 1.02)
    frames_axis(ax)
    if first:
        ax.set_ylabel("greedy accuracy")
    else:
        ax.tick_params(labelleft=False)
    for handle, text in zip(*ax.get_legend_handles_labels()):
        legend.setdefault(text, handle)
    legend.setdefault(f"blind ceiling {chance:.2f}", Line2D([], [], color="grey", lw=0.8, ls=":"))
    if any(paper.get((line.row, difficulty, aux, metric)) for line in lines):
        legend.setdefault("paper (its frames)", Line2D([], [], color="grey", marker="<", ls=""))


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
