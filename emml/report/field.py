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
(aggregate.SEED). A cell where fewer than two rows have runs is not drawn: nothing to compare, no empty panel. The
figure is a page's text wide (7 in, emml/report/savefig.py), its title wrapped to it.
Written as reports/<table>-<profile>-rliable.png and .pdf (embedded in reports/<table>-<profile>.md).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from emml.config.profiles import Profile  # noqa: E402
from emml.report.aggregate import (  # noqa: E402
    REPS,
    SEED,
    iqm,
    percentile_interval,
    probability_of_improvement,
    reference_row,
    stratified_bootstrap,
)
from emml.report.savefig import PAGE_HEIGHT_INCHES, PAGE_INCHES, save, wrap  # noqa: E402

TAUS = np.linspace(0.0, 1.0, 51)
"""The thresholds of the performance profiles (accuracy), every 0.02."""
PROFILE_REPS = 500
"""Resamples of a performance profile's band: drawn, never tabulated; the intervals reported as numbers (IQM,
P(improvement)) keep `REPS`. (Chosen when rliable's loop evaluated every threshold in Python per resample, ~2 s a
row; drawn at once now, it is kept so that the committed figures stay the same.)"""
XLIM = (-0.03, 1.03)
"""Accuracy and probability axes: a point at 0 or 1 drawn whole."""
PAPER_MARK = dict(marker="x", color="black", ms=7, mew=1.5, ls="none", zorder=2)
"""How the paper's number is drawn."""


def _profile(matrix: np.ndarray, reps: int = PROFILE_REPS, seed: int = SEED) -> tuple[np.ndarray, np.ndarray | None]:
    """The score distribution of a (runs × cells) matrix over TAUS and its 95% band (None with one run): rliable's
    `create_performance_profile`, its stratified bootstrap drawn at once (`emml.report.aggregate.stratified_bootstrap`,
    the same floats)."""
    if matrix.shape[0] < 2:
        return score_distributions(matrix[None])[0], None
    profile, values = stratified_bootstrap([matrix], score_distributions, reps, seed)
    band = np.array([percentile_interval(values[:, i]) for i in range(len(TAUS))]).T
    return profile, band


def score_distributions(scores: np.ndarray) -> np.ndarray:
    """rliable.library.score_distributions over TAUS of each (runs × cells) matrix of ``scores`` (resamples × runs ×
    cells): the fraction of its scores above each τ."""
    flat = np.asarray(scores).reshape(len(scores), -1)
    return (flat[:, :, None] > TAUS[None, None, :]).mean(axis=1)


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
    from emml.eval.metrics import BY_NAME

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
                    "label": BY_NAME[metric].label if metric in BY_NAME else labels.get(metric, metric),
                    "rows": rows,
                }
            )
    return out


ROW_INCHES = 0.2
"""The height of a row of the table in a panel; the figure is `PAGE_INCHES` wide."""


def _estimate(ax, y: float, e, color: str, name: str, several: bool) -> None:
    """A point at the estimate; with ``several`` runs its interval as a bar, else a hollow point alone."""
    if several:
        ax.plot([e.lo, e.hi], [y, y], color=color, lw=4, alpha=0.4, solid_capstyle="butt", label=f"_ci {name}")
        ax.plot([e.value], [y], "o", color=color, ms=6, zorder=3, label=f"_point {name}")
    else:
        ax.plot([e.value], [y], "o", color=color, mfc="white", mew=1.5, ms=6, zorder=3, label=f"_single {name}")


def field_figures(table, profile: Profile, cells) -> list:
    """The figures (one row of three panels per setting and metric where two rows or more have runs: one row alone
    compares with nothing), as many as it takes for each to fit a page (`PAGE_HEIGHT_INCHES`: the rows of panels
    packed in the table's order, `pages`); [] for a transfer table (every row reads the same runs) or when no such
    cell. The reference row (Dual-Attention) in bold and drawn over the others."""
    if table.transfer is not None:
        return []
    data = [d for d in panel_data(table, cells) if len(d["rows"]) >= 2]
    if not data:
        return []
    lines = max(_tick(row, 1).count("\n") + 1 for d in data for row in d["rows"])
    heights = [0.75 + ROW_INCHES * lines * len(d["rows"]) for d in data]
    cut = pages(heights)
    return [
        _figure(table, profile, [data[i] for i in page], [heights[i] for i in page], (k, len(cut)))
        for k, page in enumerate(cut, 1)
    ]


def field_figure(table, profile: Profile, cells):
    """The first of `field_figures`, or None."""
    figs = field_figures(table, profile, cells)
    for fig in figs[1:]:
        plt.close(fig)
    return figs[0] if figs else None


FRAME_INCHES = 1.4
"""A figure's height beyond its rows of panels: the title above them, the legend under them."""


def pages(heights: list[float], limit: float = PAGE_HEIGHT_INCHES) -> list[list[int]]:
    """The rows of panels (their heights) packed in order onto pages of at most ``limit`` inches with the title and
    legend (`FRAME_INCHES`); a row taller than a page alone is a page of its own."""
    out: list[list[int]] = []
    used = limit  # no page open
    for i, h in enumerate(heights):
        if out and used + h <= limit:
            out[-1].append(i)
            used += h
        else:
            out.append([i])
            used = FRAME_INCHES + h
    return out


def _figure(table, profile: Profile, data: list[dict], heights: list[float], page: tuple[int, int]):
    """One page of the field figure: ``data``'s rows of panels, page ``page`` = (k, of n)."""
    ref = reference_row(table)
    fig, axes = plt.subplots(
        len(data),
        3,
        figsize=(PAGE_INCHES, FRAME_INCHES + sum(heights)),
        squeeze=False,
        gridspec_kw={"height_ratios": heights},
        layout="constrained",
    )
    legend: dict = {}
    for i, d in enumerate(data):
        names = list(d["rows"])
        # 1. IQM per row over its runs in this cell, the paper's number beside it
        ax = axes[i][0]
        for y, row in enumerate(names[::-1]):
            k, values, paper = d["rows"][row]
            color = f"C{k % 10}"
            _estimate(ax, y, iqm([values]), color, row, len(values) > 1)
            if paper is not None:
                ax.plot([paper], [y], **PAPER_MARK, label=f"_paper {row}")
        ax.set_yticks(range(len(names)), [_tick(row, len(d["rows"][row][1])) for row in names[::-1]])
        _bold(ax, names[::-1], ref)
        ax.set_ylim(-0.6, len(names) - 0.4)
        ax.set_xlim(*XLIM)
        ax.set_xlabel("IQM over runs, 95% CI")
        ax.set_title(f"{d['setting']} · {d['label']}: IQM")
        # 2. P(reference > row) in this cell
        ax = axes[i][1]
        theirs = d["rows"][ref][1] if ref in d["rows"] else []
        others = [r for r in names if r != ref]
        for y, row in enumerate(others[::-1]):
            k, values, _ = d["rows"][row]
            if theirs:
                p = probability_of_improvement([theirs], [values])
                _estimate(ax, y, p, f"C{k % 10}", row, len(theirs) > 1 and len(values) > 1)
        ax.set_yticks(range(len(others)), [_tick(r, f"{len(theirs)} vs {len(d['rows'][r][1])}") for r in others[::-1]])
        ax.set_ylim(-0.6, max(len(others), 1) - 0.4)
        ax.axvline(0.5, color="grey", lw=0.8, ls="--")
        ax.set_xlim(*XLIM)
        ax.set_xlabel(wrap(f"P({ref} > row), 95% CI" if ref else "no reference row", 2.0, 8))
        if not theirs:
            ax.text(0.5, 0.5, f"no {ref or 'reference'} run here", ha="center", va="center", transform=ax.transAxes)
        ax.set_title("probability of improvement")
        # 3. performance profiles over the runs in this cell
        ax = axes[i][2]
        for row in names:
            k, values, _ = d["rows"][row]
            prof, band = _profile(np.asarray(values, dtype=float)[:, None])
            color = f"C{k % 10}"
            main = row == ref
            ax.plot(TAUS, prof, color=color, label=row, lw=2.2 if main else 1.0, zorder=3 if main else 2)
            if band is not None:
                ax.fill_between(TAUS, band[0], band[1], color=color, alpha=0.15, lw=0)
            legend.setdefault(row, Line2D([], [], color=color, lw=2.2 if main else 1.0))
        ax.set_xlim(0, 1)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel(f"{d['label']} τ")
        ax.set_ylabel("fraction of runs > τ")
        ax.set_title("performance profile")
    key = {
        "IQM, 95% CI (2 runs or more)": Line2D([], [], marker="o", color="grey", lw=4, alpha=0.6),
        "one run: no interval": Line2D([], [], marker="o", color="grey", mfc="white", ls="none"),
        "the paper's number": Line2D([], [], **PAPER_MARK),
    }
    handles = {**legend, **key}
    longest = max(len(t) for t in handles)
    ncol = max(1, min(len(handles), int(PAGE_INCHES * 72 / (0.6 * plt.rcParams["legend.fontsize"] * longest + 30))))
    fig.legend(list(handles.values()), list(handles), loc="outside lower center", ncol=ncol)
    name = profile.name
    part = f" ({page[0]} of {page[1]})" if page[1] > 1 else ""
    title = (
        f"{table.name} [{name}]{part}: rliable per setting and metric where two rows or more have runs; (n) = runs in "
        f"the cell; 95% CIs from resampling each cell's runs ({REPS:,} resamples, seed {SEED}; {PROFILE_REPS:,} for "
        "the profiles' bands)"
    )
    fig.suptitle(wrap(title, PAGE_INCHES - 0.1, plt.rcParams["figure.titlesize"]))
    return fig


TICK_INCHES = 1.2
"""The width a row's name takes beside a panel; longer names wrap."""


def _tick(row: str, runs) -> str:
    """A row's tick label: its name, wrapped to `TICK_INCHES`, and its runs in the cell."""
    return wrap(f"{row} ({runs})", TICK_INCHES, plt.rcParams["ytick.labelsize"])


def _bold(ax, names: list[str], ref: str | None) -> None:
    """The reference row's tick label in bold."""
    for label, row in zip(ax.get_yticklabels(), names):
        if row == ref:
            label.set_fontweight("bold")


def plot_field(table, profile: Profile, cells, out: Path) -> list[Path]:
    """`field_figures` written as reports/<table>-<profile>-rliable.png and .pdf, then -rliable-2.png and .pdf, …
    (PNG, PDF per page); [] for a transfer table or when no setting has two rows with runs. A page an earlier
    report wrote beyond these is removed (no page links it; a reader would take it for the results' own)."""
    stem = f"{table.name}-{profile.name}-rliable"
    figs = field_figures(table, profile, cells)
    paths = []
    for k, fig in enumerate(figs, 1):
        name = stem if k == 1 else f"{stem}-{k}"
        for suffix in (".png", ".pdf"):
            paths.append(save(fig, out / f"{name}{suffix}"))
        plt.close(fig)
    for old in [out / f"{stem}.png", out / f"{stem}.pdf", *out.glob(f"{stem}-*.png"), *out.glob(f"{stem}-*.pdf")]:
        if old not in paths:
            old.unlink(missing_ok=True)
    return paths
