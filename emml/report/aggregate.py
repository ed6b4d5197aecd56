"""An aggregate under each table that stays honest with few seeds (Agarwal et al. 2021, "Deep RL at the edge of the
statistical precipice"; the rliable package), comparing like with like (issue 49): per setting (difficulty × aux)
and metric, each row's interquartile mean (IQM) over its runs in that cell, with a 95% bootstrap interval, and beside
the reference row (Dual-Attention as the paper proposes it) the mean difference with its interval and the
probability that the reference beats the row. Nothing pools Aux with No Aux or Easy with Hard (until issue 49 a
row's IQM pooled every cell it had, so Dual-Attention's read its Aux and No Aux runs together beside rows with Aux
runs only); runs and cells are counted apart; a row with one run in a cell has no interval.

Statistics and intervals are rliable's (`rliable.metrics.aggregate_iqm`, `rliable.metrics.probability_of_improvement`,
`rliable.library.get_interval_estimates`: runs resampled with replacement within each cell, rliable's strata; a
percentile interval), seeded, and computed here over every resample at once (`stratified_bootstrap`): the same draws
from the same seeded generator in the same order, the same statistic per resample, the same percentiles, so the same
floats as rliable's loop (tests/report/test_aggregate.py), which called the statistic in Python once per resample and
took most of a report's time (a Table 2 page: 137 of 165 s).
rliable reads a (runs × cells) matrix: a row whose cells hold different numbers of seeds is read on the first k
seeds of every cell, k the fewest any of its cells has. (rliable.library needs `arch`, whose 7.x imports only
under pandas < 3: pyproject.toml pins pandas below 3.)
"""

from __future__ import annotations

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


def stratified_bootstrap(arrays: list[np.ndarray], statistic, reps: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """rliable's stratified bootstrap (`rliable.library.StratifiedBootstrap` for one array,
    `StratifiedIndependentBootstrap` for several) of the (runs × cells) ``arrays``, every resample at once: the
    statistic on the arrays as they are, and on each of ``reps`` resamples. Per resample and per array, rliable draws
    each cell's runs with replacement, `np.random.choice(runs, shape)`, from NumPy's legacy generator seeded with
    ``seed`` (it seeds the global one; here a `RandomState` of that seed, the same stream, and the global generator is
    left alone). Where every array has one shape, the draws of all resamples are one call (the legacy generator draws
    element by element, so the stream is the same). ``statistic`` takes the arrays with a leading resample axis
    (resamples × runs × cells) and returns a value per resample, or (resamples × k) values."""
    rng = np.random.RandomState(seed)
    shapes = [a.shape for a in arrays]
    if len(set(shapes)) == 1:
        draws = rng.choice(shapes[0][0], (reps, len(arrays), *shapes[0]), replace=True)
        indices = [draws[:, j] for j in range(len(arrays))]
    else:  # rows with different run counts: each resample's draws in rliable's order (cheap: indices only)
        indices = [np.empty((reps, *shape), dtype=np.int64) for shape in shapes]
        for r in range(reps):
            for j, shape in enumerate(shapes):
                indices[j][r] = rng.choice(shape[0], shape, replace=True)
    resampled = [a[i, np.arange(a.shape[1])] for a, i in zip(arrays, indices)]
    return np.asarray(statistic(*(a[None] for a in arrays)))[0], np.asarray(statistic(*resampled))


def percentile_interval(values: np.ndarray) -> tuple[float, float]:
    """The `CONFIDENCE` percentile interval of bootstrap ``values`` (one column), as arch's `conf_int` computes it for
    rliable (method 'percentile', two-sided)."""
    alpha = (1.0 - CONFIDENCE) / 2
    lo, hi = np.percentile(values, [100 * alpha, 100 * (1.0 - alpha)])
    return float(lo), float(hi)


def _estimate(
    arrays: list[np.ndarray], statistic, runs: int, cells: int, spread: bool, reps: int, seed: int
) -> Estimate:
    point, values = stratified_bootstrap(arrays, statistic, reps, seed)
    lo, hi = percentile_interval(values)
    return Estimate(float(point), lo, hi, runs, cells, spread)


def iqm(cells: list[list[float]], reps: int = REPS, seed: int = SEED) -> Estimate:
    """IQM over every run of every cell (rliable.metrics.aggregate_iqm: the 25%-trimmed mean), with its 95%
    stratified-bootstrap interval (runs resampled within each cell)."""
    m = _matrix([c for c in cells if len(c)])
    return _estimate([m], interquartile_means, m.size, m.shape[1], m.shape[0] > 1, reps, seed)


def interquartile_mean(scores: np.ndarray) -> float:
    """rliable.metrics.aggregate_iqm, the same float (tests/report/test_aggregate.py): scipy's 25%-trimmed mean over
    every score, computed with the same partition and mean, without scipy's dispatch: 16 µs a call where rliable's
    takes 195 (a 3-run cell), which over a table's bootstrap resamples was more than half of `make reports`."""
    return float(interquartile_means(np.asarray(scores)[None])[0])


def interquartile_means(scores: np.ndarray) -> np.ndarray:
    """`interquartile_mean` of each (runs × cells) matrix of ``scores`` (resamples × runs × cells): each partitioned
    and averaged along its own row, as the one-matrix computation does."""
    a = np.asarray(scores).reshape(len(scores), -1)
    low = int(0.25 * a.shape[1])
    high = a.shape[1] - low
    return np.mean(np.partition(a, (low, high - 1), axis=1)[:, low:high], axis=1)


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
    return _estimate([x, y], improvements, x.size + y.size, len(pairs), x.shape[0] > 1 or y.shape[0] > 1, reps, seed)


def improvement(x: np.ndarray, y: np.ndarray) -> float:
    """rliable.metrics.probability_of_improvement of (runs × cells) scores ``x`` over ``y``, computed at once for
    every cell: per cell the Mann-Whitney U of x over y (pairs where x is higher, ties half) over the pairs, then the
    mean over cells (tests/report/test_aggregate.py: equal to rliable's). rliable's calls scipy once per cell and
    resample: 86 of the 98 s a Table 2 report took."""
    return float(improvements(np.asarray(x)[None], np.asarray(y)[None])[0])


def improvements(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """`improvement` of each resample: ``x`` (resamples × runs × cells) over ``y`` (resamples × runs' × cells)."""
    higher = (x[:, :, None, :] > y[:, None, :, :]).sum(axis=(1, 2))
    ties = (x[:, :, None, :] == y[:, None, :, :]).sum(axis=(1, 2))
    per_cell = (higher + 0.5 * ties) / (x.shape[1] * y.shape[1])
    return per_cell.mean(axis=1)


def reference_row(table) -> str | None:
    """The row the others are compared with: the table's Dual-Attention model as the paper proposes it (no
    overrides): 'Dual-Attention' in Tables 2 and 5, 'DA Multi-Task' in Table 3; None for a transfer table."""
    if table.transfer is not None:
        return None
    for row in table.rows:
        if row.model == "dual_attention" and not row.overrides and not row.metric_overrides:
            return row.label
    return None


def mean_difference(x: list[float], y: list[float], reps: int = REPS, seed: int = SEED) -> Estimate:
    """mean(x) - mean(y) over one cell's runs, with its 95% percentile interval from resampling each row's runs with
    replacement (a Generator seeded with ``seed``); no interval (``spread`` False) when either row has one run:
    resampling one run cannot move it."""
    x_, y_ = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    value = float(x_.mean() - y_.mean())
    if len(x_) < 2 or len(y_) < 2:
        return Estimate(value, value, value, len(x_) + len(y_), 1, False)
    rng = np.random.default_rng(seed)
    diffs = x_[rng.integers(0, len(x_), (reps, len(x_)))].mean(1) - y_[rng.integers(0, len(y_), (reps, len(y_)))].mean(
        1
    )
    lo, hi = percentile_interval(diffs)
    return Estimate(value, lo, hi, len(x_) + len(y_), 1, True)


@dataclass
class Comparison:
    """One row in one cell (a setting: difficulty × aux, and a metric) against the reference row in the same cell."""

    difficulty: str
    aux: bool
    metric: str
    row: str
    iqm: Estimate
    """The row's IQM over its runs in the cell."""
    difference: Estimate | None = None
    """mean(reference) - mean(row) in the cell; None for the reference row or when the reference has no run there."""
    improvement: Estimate | None = None
    """P(reference > row) in the cell, rliable's; None as `difference`."""
    reference_runs: int = 0
    """Runs of the reference row in the cell."""


def compare(table, cells) -> list[Comparison]:
    """Per setting (difficulty × aux: Aux and No Aux apart, Easy and Hard apart) and metric, every row with runs in
    that cell: its IQM, and beside the reference row's runs in the same cell the mean difference and P(reference >
    row). A row without runs in a setting is not compared there; nothing pools cells of different settings."""
    ref = reference_row(table)
    by = {(c.row, c.difficulty, c.aux, c.metric): c.values for c in cells}
    out = []
    for difficulty, aux, metric in table.columns():
        theirs = by.get((ref, difficulty, aux, metric), [])  # no reference row (ref None): no cell, none
        for row in (r.label for r in table.rows):
            own = by.get((row, difficulty, aux, metric))
            if not own:
                continue
            c = Comparison(difficulty, aux, metric, row, iqm([own]), reference_runs=len(theirs))
            if theirs and row != ref:
                c.difference = mean_difference(theirs, own)
                p = probability_of_improvement([theirs], [own])
                one = len(theirs) < 2 or len(own) < 2  # one run on a side: resampling has nothing to move
                c.improvement = Estimate(p.value, p.value, p.value, p.runs, 1, False) if one else p
            out.append(c)
    return out


def _runs(n: int) -> str:
    return f"{n} run{'s' if n != 1 else ''}"


def _show(e: Estimate, what: str, signed: bool = False) -> str:
    value = f"{e.value:+.2f}" if signed else f"{e.value:.2f}"
    if not e.spread:
        return f"{value} ({what}: no interval)"
    lo, hi = (f"{e.lo:+.2f}", f"{e.hi:+.2f}") if signed else (f"{e.lo:.2f}", f"{e.hi:.2f}")
    return f"{value} [{lo}, {hi}] ({what})"


def summary(table, cells) -> tuple[list[dict[str, str]], str] | None:
    """The aggregate's lines, one per setting and row with runs there (Setting, row, then per metric its IQM, the
    mean difference to the reference row and P(reference > row)), and the footer saying what they are. None for a
    transfer table (every row reads the same runs) or when no row has runs."""
    from emml.config.env_kinds import env_label

    if table.transfer is not None or not any(c.values for c in cells):
        return None
    ref = reference_row(table)
    labels = {v: k for k, v in table.metrics.items()}
    lines: dict[tuple, dict[str, str]] = {}
    for c in compare(table, cells):
        setting = f"{env_label(c.difficulty)} · {'Aux' if c.aux else 'No Aux'}"
        line = lines.setdefault((setting, c.row), {"Setting": setting, table.row_header: c.row})
        label = labels[c.metric]  # a comparison reads a column of the table: its metric is one of the table's
        line[f"{label} IQM [95% CI]"] = _show(c.iqm, _runs(c.iqm.runs) + " in 1 cell")
        if ref is None:
            continue
        if c.difference is not None:
            runs = f"{c.reference_runs} vs {_runs(c.iqm.runs)} in 1 cell"
            line[f"{label}: {ref} − row [95% CI]"] = _show(c.difference, runs, signed=True)
            line[f"{label}: P({ref} > row)"] = _show(c.improvement, runs)
        elif c.row != ref:
            line[f"{label}: {ref} − row [95% CI]"] = line[f"{label}: P({ref} > row)"] = (
                f"{MISSING} ({ref}: no run here)"
            )
    present = list(dict.fromkeys(k for line in lines.values() for k in line))  # ordered: the same bytes each time
    order = ["Setting", table.row_header]  # then each metric's three columns, in the table's metric order
    order += [k for label in labels.values() for k in (f"{label} IQM", f"{label}: {ref} − row", f"{label}: P({ref} >")]
    columns = sorted(present, key=lambda k: next(i for i, o in enumerate(order) if k.startswith(o)))
    out = [{k: line.get(k, "") for k in columns} for line in lines.values()]
    compare_text = (
        f" {ref} − row = the difference of the two rows' means in that cell, with its 95% percentile interval from "
        f"resampling each row's runs with replacement ({REPS:,} resamples, seed {SEED}); P({ref} > row) = the "
        f"probability that a run of {ref} scores higher than a run of the row in the same cell (ties count half; "
        "rliable.metrics.probability_of_improvement), with its 95% interval from the same resampling "
        "(rliable.library.get_interval_estimates). Read the difference beside the probability: P = 1.00 says every "
        "run is ahead, not by how much."
        if ref is not None
        else ""
    )
    footer = (
        "Aggregate per setting (difficulty × aux: Aux and No Aux apart, Easy and Hard apart) and metric, so that rows "
        "compare like with like: each number reads one cell of the table above, over the runs (seeds) it holds, and "
        "a row with no run in a setting is not compared there; runs and cells are counted apart. IQM = the "
        "interquartile mean of a row's runs (rliable.metrics.aggregate_iqm; Agarwal et al. 2021; with 3 runs or fewer "
        "it is their mean), with a 95% bootstrap percentile interval (the cell's runs resampled with replacement, "
        f"{REPS:,} resamples, seed {SEED}).{compare_text} Where a row has one run in the cell, resampling has nothing "
        "to move: no interval is given, and the number is one seed's. With three seeds or fewer the intervals are "
        "wide: read them, not the point alone; whether a claim holds is decided on the claims page "
        "(claims-<profile>.md) against the evaluation's binomial error."
    )
    return out, footer
