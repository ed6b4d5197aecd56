"""An aggregate under each table that stays honest with few seeds (Agarwal et al. 2021, "Deep RL at the edge of the
statistical precipice"; the rliable package): per metric, each row's interquartile mean (IQM) over its runs in every
cell, with a 95% stratified-bootstrap interval, and the probability that Dual-Attention beats each other row.

Statistics and intervals are rliable's (`rliable.metrics.aggregate_iqm`, `rliable.metrics.probability_of_improvement`,
`rliable.library.get_interval_estimates`: runs resampled with replacement within each cell, rliable's strata; a
percentile interval), seeded: rliable draws from NumPy's global generator, seeded for the call, then restored.
rliable reads a (runs × cells) matrix: a row whose cells hold different numbers of seeds is read on the first k
seeds of every cell, k the fewest any of its cells has. (rliable.library needs `arch`, whose 7.x imports only
under pandas < 3: pyproject.toml pins pandas below 3.)
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

REPS = 2000
"""Bootstrap resamples per interval."""
SEED = 0
"""Every interval draws from a Generator seeded with this: a report is reproducible to the digit."""
CONFIDENCE = 0.95
MISSING = "—"


@dataclass
class Estimate:
    """A point estimate with its stratified-bootstrap interval."""

    value: float
    """The statistic on the runs as they are."""
    lo: float
    """Lower end of the percentile interval."""
    hi: float
    """Upper end of the percentile interval."""
    runs: int
    """Scores (runs × cells) the statistic read."""
    cells: int
    """Cells (tasks, rliable's strata) the runs come from."""
    spread: bool
    """False when no cell has two runs: resampling cannot move the statistic, the interval is the point."""


def _matrix(cells: list) -> np.ndarray:
    """(runs × cells) scores for rliable: every cell cut to the fewest runs any of them has (seed order)."""
    k = min(len(c) for c in cells)
    return np.array([np.asarray(c, dtype=float)[:k] for c in cells]).T


def _estimate(scores: dict, func, runs: int, cells: int, spread: bool, reps: int, seed: int) -> Estimate:
    from rliable import library

    saved = np.random.get_state()
    np.random.seed(seed)  # rliable draws its resampling indices from the global generator: seeded, then restored
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)  # arch on rliable's random_state argument
            points, intervals = library.get_interval_estimates(
                scores, func, reps=reps, confidence_interval_size=CONFIDENCE, random_state=np.random.RandomState(seed)
            )
    finally:
        np.random.set_state(saved)
    (key,) = scores
    lo, hi = intervals[key][:, 0]
    return Estimate(float(points[key][0]), float(lo), float(hi), runs, cells, spread)


def iqm(cells: list[list[float]], reps: int = REPS, seed: int = SEED) -> Estimate:
    """IQM over every run of every cell (rliable.metrics.aggregate_iqm: the 25%-trimmed mean), with its 95%
    stratified-bootstrap interval (runs resampled within each cell)."""
    from rliable import metrics

    m = _matrix([c for c in cells if len(c)])
    func = lambda x: np.array([metrics.aggregate_iqm(x)])  # noqa: E731 - rliable's idiom
    return _estimate({"row": m}, func, m.size, m.shape[1], m.shape[0] > 1, reps, seed)


def probability_of_improvement(
    x_cells: list[list[float]], y_cells: list[list[float]], reps: int = REPS, seed: int = SEED
) -> Estimate | None:
    """P(X > Y): the probability that a run of X scores higher than a run of Y in the same cell (ties count half),
    averaged over the cells both have runs in (rliable.metrics.probability_of_improvement), with its 95% interval
    from resampling each row's runs within each cell. None: no cell in common."""
    pairs = [(x, y) for x, y in zip(x_cells, y_cells) if len(x) and len(y)]
    if not pairs:
        return None
    x, y = _matrix([p[0] for p in pairs]), _matrix([p[1] for p in pairs])
    func = lambda a, b: np.array([improvement(a, b)])  # noqa: E731 - rliable's idiom
    return _estimate({"pair": (x, y)}, func, x.size + y.size, len(pairs), x.shape[0] > 1 or y.shape[0] > 1, reps, seed)


def improvement(x: np.ndarray, y: np.ndarray) -> float:
    """rliable.metrics.probability_of_improvement of (runs × cells) scores ``x`` over ``y``, computed at once for
    every cell: per cell the Mann-Whitney U of x over y (pairs where x is higher, ties half) over the pairs, then the
    mean over cells (tests/report/test_aggregate.py: equal to rliable's). rliable's calls scipy once per cell and
    resample: 86 of the 98 s a Table 2 report took."""
    higher = (x[:, None, :] > y[None, :, :]).sum(axis=(0, 1))
    ties = (x[:, None, :] == y[None, :, :]).sum(axis=(0, 1))
    per_cell = (higher + 0.5 * ties) / (x.shape[0] * y.shape[0])
    return np.mean(list(per_cell))  # the mean of a list of numpy floats, as rliable takes it: the same float


def reference_row(table) -> str | None:
    """The row the others are compared with: the table's Dual-Attention model as the paper proposes it (no
    overrides): 'Dual-Attention' in Tables 2 and 5, 'DA Multi-Task' in Table 3; None for a transfer table."""
    if table.transfer is not None:
        return None
    for row in table.rows:
        if row.model == "dual_attention" and not row.overrides and not row.metric_overrides:
            return row.label
    return None


def _show(e: Estimate) -> str:
    where = f"n={e.runs}" + (f" in {e.cells} cells" if e.cells > 1 else "")
    if not e.spread:
        return f"{e.value:.2f} ({where}, no interval)"
    return f"{e.value:.2f} [{e.lo:.2f}, {e.hi:.2f}] ({where})"


def summary(table, cells) -> tuple[dict[str, dict[str, str]], str] | None:
    """Row label → column → text: each row's IQM per metric and P(reference > row) per metric, over the cells
    (difficulty × aux) of the metric, for the rows that have runs; and the footer saying what they are. None for a
    transfer table (every row reads the same runs) or when no row has runs."""
    if table.transfer is not None or not any(c.values for c in cells):
        return None
    ref = reference_row(table)
    by: dict[tuple[str, str], dict] = {}
    for c in cells:
        by.setdefault((c.row, c.metric), {})[(c.difficulty, c.aux)] = c.values
    out: dict[str, dict[str, str]] = {}
    for label, metric in table.metrics.items():
        for row in (r.label for r in table.rows):
            own = by.get((row, metric), {})
            if not any(own.values()):
                continue
            out.setdefault(row, {})[f"{label} IQM [95% CI]"] = _show(iqm(list(own.values())))
            if ref is None or row == ref:
                continue
            theirs = by.get((ref, metric), {})
            keys = [k for k in own if own[k] and theirs.get(k)]
            p = probability_of_improvement([theirs[k] for k in keys], [own[k] for k in keys])
            column = f"P({ref} > row), {label}"
            out[row][column] = MISSING if p is None else _show(p)
    if not out:
        return None
    columns = list(dict.fromkeys(k for row in out.values() for k in row))
    out = {row: {c: values.get(c, "") for c in columns} for row, values in out.items()}
    compare = (
        f" P({ref} > row) = the probability that a run of {ref} scores higher than a run of the row in the same cell "
        "(ties count half; rliable.metrics.probability_of_improvement), averaged over the cells both have runs in, "
        "with its 95% interval from resampling both rows' runs within each cell."
        if ref is not None
        else ""
    )
    footer = (
        "Aggregate per metric over the table's cells (rliable; Agarwal et al. 2021): IQM = the interquartile mean of "
        "a row's runs over every cell (the mean of the middle 50% of scores, rliable.metrics.aggregate_iqm), with a "
        f"95% stratified-bootstrap percentile interval (each cell's runs resampled with replacement, {REPS:,} "
        f"resamples, seed {SEED}; rliable.library.get_interval_estimates).{compare} n = runs read (a row whose cells "
        "hold unequal numbers of seeds is read on the first k of each, k the fewest); one run per cell has nothing to "
        "resample: no "
        "interval. With three seeds or fewer the intervals are wide: read them, not the point alone."
    )
    return out, footer
