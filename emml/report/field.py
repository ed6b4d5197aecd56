"""The field's three figures under each table (Agarwal et al. 2021, "Deep RL at the edge of the statistical
precipice"; issues 49 and 60), computed with rliable, one row of panels per setting (difficulty × aux: Aux and No Aux
apart, Easy and Hard apart) and metric (SGN and EQA apart: the table's own columns, never one number pooling them):

- the IQM per row over its runs in that cell, with its 95% bootstrap interval (`emml.report.aggregate.iqm`), and the
  paper's number for the row where its table has one (reproduce/paper/<table>.csv, read as the table prints it);
- the probability of improvement of the reference row (Dual-Attention as the paper proposes it) over each other row
  in that cell, with its interval (`emml.report.aggregate.probability_of_improvement`);
- performance profiles: per row the fraction of its runs scoring above τ, with 95% bands
  (`rliable.library.create_performance_profile`).

n is always a number of runs (seeds) in the cell. A row with one run in a cell is a hollow point with no interval
(resampling one run cannot move it); a filled point with a bar is an IQM with its interval. Every bootstrap is seeded
(aggregate.SEED). A cell with no run is not drawn: no empty panel. The title is wrapped to the figure's width.
Written as reports/<table>-<profile>-rliable.png and .pdf (embedded in reports/<table>-<profile>.md).
"""

from __future__ import annotations

import textwrap
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from emml.report.aggregate import REPS, SEED, iqm, probability_of_improvement, reference_row  # noqa: E402
from emml.report.savefig import save  # noqa: E402

TAUS = np.linspace(0.0, 1.0, 51)
"""The thresholds of the performance profiles (accuracy), every 0.02."""
PROFILE_REPS = 500
"""Resamples of a performance profile's band: drawn, never tabulated, and rliable's profile bootstrap evaluates
every threshold in Python per resample (2,000 resamples over 101 thresholds took ~2 s per row, most of a table's
report); the intervals reported as numbers (IQM, P(improvement)) keep `REPS`."""
WIDTH = 11.0
"""The figure's width in inches; the title is wrapped to it."""
XLIM = (-0.03, 1.03)
"""Accuracy and probability axes: a point at 0 or 1 drawn whole."""
PAPER_MARK = dict(marker="x", color="black", ms=7, mew=1.5, ls="none", zorder=2)
"""How the paper's number is drawn."""


def _profile(matrix: np.ndarray, reps: int = PROFILE_REPS, seed: int = SEED) -> tuple[np.ndarray, np.ndarray | None]:
    """The score distribution of a (runs × cells) matrix over TAUS and its 95% band (None with one run),
    rliable's, its bootstrap drawing from NumPy's global generator seeded for the call, then restored."""
    from rliable import library

    if matrix.shape[0] < 2:
        return library.score_distributions(matrix, TAUS), None
    saved = np.random.get_state()
    np.random.seed(seed)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            profiles, cis = library.create_performance_profile({"row": matrix}, TAUS, reps=reps)
    finally:
        np.random.set_state(saved)
    return profiles["row"], cis["row"]


def paper_value(text) -> float | None:
    """The paper's number as a float ('0.96' -> 0.96); None where the paper has no number for the cell."""
    try:
        value = float(str(text).strip())
    except (TypeError, ValueError):
        return None
    return value if np.isfinite(value) else None


def panel_data(table, cells) -> list[dict]:
    """Per cell column of the table with runs (setting × metric, in the table's order): its setting, its metric,
    and per row with runs there (in the table's row order) its index in the table, its runs' values (seed order) and
    the paper's number (None where the paper has none)."""
    from emml.config.env_kinds import env_label
    from emml.experiments.tables import METRIC_LABELS

    by = {(c.row, c.difficulty, c.aux, c.metric): c for c in cells}
    labels = {v: k for k, v in table.metrics.items()}
    out = []
    for difficulty, aux, metric in table.columns():
        rows = {}
        for k, row in enumerate(r.label for r in table.rows):
            c = by.get((row, difficulty, aux, metric))
            if c is not None and c.values:
                rows[row] = (k, [float(v) for v in c.values], paper_value(c.paper))
        if rows:
            out.append(
                {
                    "setting": f"{env_label(difficulty)} · {'Aux' if aux else 'No Aux'}",
                    "metric": metric,
                    "label": METRIC_LABELS.get(metric, labels.get(metric, metric)),
                    "rows": rows,
                }
            )
    return out


def _runs(n: int) -> str:
    return f"n={n} run{'s' if n != 1 else ''}"


def _estimate(ax, y: float, e, color: str, name: str, several: bool) -> None:
    """A point at the estimate; with ``several`` runs its interval as a bar, else a hollow point alone."""
    if several:
        ax.plot([e.lo, e.hi], [y, y], color=color, lw=4, alpha=0.4, solid_capstyle="butt", label=f"_ci {name}")
        ax.plot([e.value], [y], "o", color=color, ms=6, zorder=3, label=f"_point {name}")
    else:
        ax.plot([e.value], [y], "o", color=color, mfc="white", mew=1.5, ms=6, zorder=3, label=f"_single {name}")


def field_figure(table, profile: str, cells):
    """The figure (one row of three panels per setting and metric with runs); None for a transfer table (every row
    reads the same runs) or when no row has runs."""
    if table.transfer is not None:
        return None
    data = panel_data(table, cells)
    if not data:
        return None
    ref = reference_row(table)
    heights = [0.9 + 0.26 * max(len(d["rows"]), 2) for d in data]
    fig, axes = plt.subplots(
        len(data),
        3,
        figsize=(WIDTH, 0.9 + sum(heights) + 0.3 * len(data)),
        squeeze=False,
        gridspec_kw={"height_ratios": heights},
        layout="constrained",
    )
    for i, d in enumerate(data):
        names = list(d["rows"])
        where = f"{d['setting']} · {d['label']}"
        # 1. IQM per row over its runs in this cell, the paper's number beside it
        ax = axes[i][0]
        ticks = []
        for y, row in enumerate(names[::-1]):
            k, values, paper = d["rows"][row]
            color = f"C{k % 10}"
            _estimate(ax, y, iqm([values]), color, row, len(values) > 1)
            if paper is not None:
                ax.plot([paper], [y], **PAPER_MARK, label=f"_paper {row}")
            ticks.append(f"{row} ({_runs(len(values))})")
        ax.set_yticks(range(len(names)), ticks)
        ax.set_ylim(-0.6, max(len(names), 2) - 0.4)
        ax.set_xlim(*XLIM)
        ax.set_xlabel(f"{d['label']}: IQM over runs, 95% CI")
        ax.set_title(f"{where}: IQM per row")
        # 2. P(reference > row) in this cell
        ax = axes[i][1]
        theirs = d["rows"][ref][1] if ref in d["rows"] else []
        others = [r for r in names if r != ref]
        ticks = []
        for y, row in enumerate(others[::-1]):
            k, values, _ = d["rows"][row]
            ticks.append(f"{row} (n={len(theirs)} vs {len(values)})")
            if theirs:
                p = probability_of_improvement([theirs], [values])
                _estimate(ax, y, p, f"C{k % 10}", row, len(theirs) > 1 and len(values) > 1)
        ax.set_yticks(range(len(others)), ticks)
        ax.set_ylim(-0.6, max(len(others), 2) - 0.4)
        ax.axvline(0.5, color="grey", lw=0.8, ls="--")
        ax.set_xlim(*XLIM)
        ax.set_xlabel(f"{d['label']}: P({ref} > row), 95% CI" if ref else "no reference row")
        if not theirs or not others:
            why = f"no {ref or 'reference'} run in this cell" if not theirs else "no other row run in this cell"
            ax.text(0.5, 0.5, why, ha="center", va="center", transform=ax.transAxes)
        ax.set_title("probability of improvement")
        # 3. performance profiles over the runs in this cell
        ax = axes[i][2]
        for row in names:
            k, values, _ = d["rows"][row]
            prof, band = _profile(np.asarray(values, dtype=float)[:, None])
            color = f"C{k % 10}"
            ax.plot(TAUS, prof, color=color, label=f"{row} ({_runs(len(values))})")
            if band is not None:
                ax.fill_between(TAUS, band[0], band[1], color=color, alpha=0.15, lw=0)
        ax.set_xlim(0, 1)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel(f"{d['label']} τ")
        ax.set_ylabel("fraction of runs > τ")
        ax.set_title("performance profile")
        ax.legend(fontsize=6, loc="center left", bbox_to_anchor=(1.01, 0.5))
    key = [
        Line2D([], [], marker="o", color="grey", lw=4, alpha=0.6, label="IQM with its 95% CI (2 runs or more)"),
        Line2D([], [], marker="o", color="grey", mfc="white", ls="none", label="one run: its score, no interval"),
        Line2D([], [], **PAPER_MARK, label="the paper's number"),
    ]
    fig.legend(handles=key, loc="outside lower center", ncol=3, fontsize=7)
    title = (
        f"{table.name} [{profile}]: rliable per setting and metric (SGN and EQA apart), n = runs in the cell; "
        f"95% CIs from resampling each cell's runs ({REPS:,} resamples, seed {SEED}; {PROFILE_REPS:,} for the "
        "profiles' bands)"
    )
    fig.suptitle(textwrap.fill(title, width=int(WIDTH * 72 / (0.62 * plt.rcParams["figure.titlesize"]))))
    return fig


def plot_field(table, profile: str, cells, out: Path) -> list[Path]:
    """`field_figure` written as reports/<table>-<profile>-rliable.png and .pdf; [] for a transfer table or when no
    row has runs."""
    fig = field_figure(table, profile, cells)
    if fig is None:
        return []
    paths = [out / f"{table.name}-{profile}-rliable.png", out / f"{table.name}-{profile}-rliable.pdf"]
    for p in paths:
        save(fig, p)
    plt.close(fig)
    return paths
