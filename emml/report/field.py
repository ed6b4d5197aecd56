"""The field's three figures under each table (Agarwal et al. 2021, "Deep RL at the edge of the statistical
precipice"; issue 49), computed with rliable, per setting (difficulty × aux: Aux and No Aux apart, Easy and Hard
apart), over the table's metrics in that setting as rliable's tasks:

- the aggregate IQM per row with its 95% stratified-bootstrap interval (`emml.report.aggregate.iqm`);
- the probability of improvement of the reference row (Dual-Attention as the paper proposes it) over each other row,
  with its interval, over the cells both have runs in (`emml.report.aggregate.probability_of_improvement`);
- performance profiles: per row the fraction of its runs × cells scoring above τ, with 95% bands
  (`rliable.library.create_performance_profile`).

Every bootstrap is seeded (aggregate.SEED); a row with one run per cell has no interval (the point is drawn alone).
A setting with no run is not drawn: no empty panel. Written as reports/<table>-<profile>-rliable.png and .pdf.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from emml.report.aggregate import REPS, SEED, iqm, probability_of_improvement, reference_row  # noqa: E402
from emml.report.savefig import save  # noqa: E402

TAUS = np.linspace(0.0, 1.0, 51)
"""The thresholds of the performance profiles (accuracy), every 0.02."""
PROFILE_REPS = 500
"""Resamples of a performance profile's band: drawn, never tabulated, and rliable's profile bootstrap evaluates
every threshold in Python per resample (2,000 resamples over 101 thresholds took ~2 s per row, most of a table's
report); the intervals reported as numbers (IQM, P(improvement)) keep `REPS`."""


def _profile(matrix: np.ndarray, reps: int = PROFILE_REPS, seed: int = SEED) -> tuple[np.ndarray, np.ndarray | None]:
    """The score distribution of a (runs × cells) matrix over TAUS and its 95% band (None with one run per cell),
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


def setting_data(table, cells) -> list[dict]:
    """Per setting with runs: its label and per row with runs there its cells' values (one list per metric, in the
    table's metric order, empty where the row has no run)."""
    from emml.config.env_kinds import env_label

    by = {(c.row, c.difficulty, c.aux, c.metric): c.values for c in cells}
    metrics = list(dict.fromkeys(table.metrics.values()))
    out = []
    for difficulty in table.difficulties:
        for aux in table.aux:
            rows = {}
            for k, row in enumerate(r.label for r in table.rows):
                values = [list(by.get((row, difficulty, aux, m), [])) for m in metrics]
                if any(values):
                    rows[row] = (k, values)
            if rows:
                label = f"{env_label(difficulty)} · {'Aux' if aux else 'No Aux'}"
                out.append({"setting": label, "rows": rows, "metrics": metrics})
    return out


def plot_field(table, profile: str, cells, out: Path) -> list[Path]:
    """The three figures per setting in one figure (a row of panels per setting); [] for a transfer table (every
    row reads the same runs) or when no row has runs."""
    from emml.experiments.tables import METRIC_LABELS

    if table.transfer is not None:
        return []
    data = setting_data(table, cells)
    if not data:
        return []
    ref = reference_row(table)
    fig, axes = plt.subplots(
        len(data),
        3,
        figsize=(11, 0.6 + 0.28 * max(len(d["rows"]) for d in data) * len(data) + 1.4 * len(data)),
        squeeze=False,
    )
    for i, d in enumerate(data):
        names = list(d["rows"])
        tasks = ", ".join(METRIC_LABELS.get(m, m) for m in d["metrics"])
        # 1. IQM per row
        ax = axes[i][0]
        for y, row in enumerate(names[::-1]):
            k, values = d["rows"][row]
            e = iqm([v for v in values if v])
            color = f"C{k % 10}"
            if e.spread:
                ax.plot([e.lo, e.hi], [y, y], color=color, lw=4, alpha=0.5, solid_capstyle="butt")
            ax.plot([e.value], [y], "|", color=color, ms=12, mew=2)
        ax.set_yticks(range(len(names)), names[::-1])
        ax.set_xlim(0, 1)
        ax.set_xlabel(f"IQM over runs × cells ({tasks})")
        ax.set_title(f"{d['setting']}: aggregate IQM, 95% CI")
        # 2. P(reference > row)
        ax = axes[i][1]
        theirs = d["rows"].get(ref, (0, []))[1] if ref is not None else []
        others = [r for r in names if r != ref]
        ys = []
        for y, row in enumerate(others[::-1]):
            k, values = d["rows"][row]
            p = probability_of_improvement(theirs, values) if theirs else None
            if p is None:
                continue
            ys.append(y)
            color = f"C{k % 10}"
            one = min(len(v) for v in theirs if v) < 2 or min(len(v) for v in values if v) < 2
            if p.spread and not one:
                ax.plot([p.lo, p.hi], [y, y], color=color, lw=4, alpha=0.5, solid_capstyle="butt")
            ax.plot([p.value], [y], "|", color=color, ms=12, mew=2)
        ax.set_yticks(range(len(others)), others[::-1])
        ax.axvline(0.5, color="grey", lw=0.8, ls="--")
        ax.set_xlim(0, 1)
        ax.set_xlabel(f"P({ref} > row), 95% CI")
        if not ys:
            why = f"no {ref or 'reference'} run in this setting" if not theirs else "no other row run in this setting"
            ax.text(0.5, 0.5, why, ha="center", va="center", transform=ax.transAxes)
        ax.set_title("probability of improvement")
        # 3. performance profiles
        ax = axes[i][2]
        for row in names:
            k, values = d["rows"][row]
            present = [v for v in values if v]
            n = min(len(v) for v in present)
            matrix = np.array([np.asarray(v, dtype=float)[:n] for v in present]).T
            prof, band = _profile(matrix)
            color = f"C{k % 10}"
            ax.plot(TAUS, prof, color=color, label=f"{row} (n={matrix.size})")
            if band is not None:
                ax.fill_between(TAUS, band[0], band[1], color=color, alpha=0.15, lw=0)
        ax.set_xlim(0, 1)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("accuracy τ")
        ax.set_ylabel("fraction of runs × cells > τ")
        ax.set_title("performance profile")
        ax.legend(fontsize=6, loc="lower left")
    fig.suptitle(
        f"{table.name} [{profile}]: rliable per setting (runs resampled within cells, {REPS:,} resamples, seed "
        f"{SEED}, {PROFILE_REPS:,} for the profiles' bands; a bar: the 95% interval, none where a row has one run per "
        "cell)"
    )
    fig.tight_layout()
    paths = [out / f"{table.name}-{profile}-rliable.png", out / f"{table.name}-{profile}-rliable.pdf"]
    for p in paths:
        save(fig, p)
    plt.close(fig)
    return paths
