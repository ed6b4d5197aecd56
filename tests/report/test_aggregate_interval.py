"""The aggregate's intervals checked at the level they state, against computations of their own (issue 66): the
percentile bootstrap's interval is the (α/2, 1 - α/2) quantiles of the statistic over every resample, and with a few
runs every resample can be listed (n runs: n**n equally likely draws with replacement), so the exact distribution is
at hand; scipy.stats.bootstrap gives the same interval by its own resampling. A 90% interval labelled 95% puts 5% of
the distribution below its lower end, not 2.5%: these tests fail on it (`test_the_aggregate_under_the_table` checked
the interval by a regex only)."""

from __future__ import annotations

import itertools
import re

import numpy as np
import pytest
import scipy.stats

from emml.experiments.tables import load_table
from emml.report.aggregate import REPS, iqm, mean_difference, summary
from emml.report.cells import Cell

TOLERANCE = 0.0125
"""How far the share of the exact distribution below an interval's end may sit from α/2: the interval reads REPS (2,000)
resamples, whose α/2-quantile lies within sqrt(0.025 · 0.975 / 2000) = 0.0035 of it (one standard error), so this is
3.5 of them; the same end at the next level (a 90% interval's 5%) is 7 of them away."""

X, Y = [0.9, 0.55, 0.72, 0.61], [0.12, 0.6, 0.23, 0.41]
"""Made-up scores of two rows in one cell, four runs each (no ties, no grid): 4**4 × 4**4 = 65,536 resamples."""


def _resampled(values, statistic=np.mean) -> np.ndarray:
    """``statistic`` over each of the n**n equally likely resamples of ``values`` (drawn with replacement)."""
    v = np.asarray(values, dtype=float)
    draws = v[np.array(list(itertools.product(range(len(v)), repeat=len(v))))]
    return np.array([statistic(d) for d in draws])


def _difference_distribution(x, y) -> np.ndarray:
    """mean(x*) - mean(y*) over every pair of resamples, each row resampled apart (as `mean_difference` does)."""
    return (_resampled(x)[:, None] - _resampled(y)[None, :]).ravel()


def _check_ends(dist: np.ndarray, lo: float, hi: float, level: float, slack: float = 0.0) -> None:
    """``lo`` and ``hi`` are the distribution's (α/2, 1 - α/2) quantiles for α = 1 - level, within TOLERANCE of
    the share; ``slack``: how far each printed end may be from the number it rounds."""
    tail = (1 - level) / 2
    assert np.mean(dist < lo - slack) <= tail + TOLERANCE, f"more than {tail:.1%} of the resamples below {lo}"
    assert np.mean(dist <= lo + slack) >= tail - TOLERANCE, f"less than {tail:.1%} of the resamples below {lo}"
    assert np.mean(dist > hi + slack) <= tail + TOLERANCE, f"more than {tail:.1%} of the resamples above {hi}"
    assert np.mean(dist >= hi - slack) >= tail - TOLERANCE, f"less than {tail:.1%} of the resamples above {hi}"


def test_the_mean_difference_interval_is_the_95_percent_one_of_the_exact_bootstrap():
    e = mean_difference(X, Y)
    dist = _difference_distribution(X, Y)
    assert e.value == pytest.approx(np.mean(X) - np.mean(Y)) and e.spread
    _check_ends(dist, e.lo, e.hi, 0.95)
    with pytest.raises(AssertionError):  # the test's own power: the same ends do not pass as a 90% interval
        _check_ends(dist, e.lo, e.hi, 0.90)


def test_the_mean_difference_interval_is_scipys_percentile_bootstrap():
    """scipy.stats.bootstrap, each sample resampled apart (paired=False), percentile method, at 95%: the same ends
    within half the distance between the exact 95% and 90% ends (Monte Carlo error of 2,000 resamples aside)."""
    e = mean_difference(X, Y)
    ci = scipy.stats.bootstrap(
        (np.array(X), np.array(Y)),
        lambda a, b, axis=-1: a.mean(axis) - b.mean(axis),
        confidence_level=0.95,
        n_resamples=50_000,
        method="percentile",
        vectorized=True,
        rng=np.random.default_rng(1),
    ).confidence_interval
    dist = _difference_distribution(X, Y)
    q95, q90 = np.quantile(dist, [0.025, 0.975]), np.quantile(dist, [0.05, 0.95])
    assert abs(e.lo - ci.low) < abs(q95[0] - q90[0]) / 2
    assert abs(e.hi - ci.high) < abs(q95[1] - q90[1]) / 2
    assert abs(ci.low - q95[0]) < 0.01 and abs(ci.high - q95[1]) < 0.01  # scipy's is the exact one too


def test_the_iqm_interval_is_the_95_percent_one_of_the_exact_bootstrap():
    """One cell of five runs: rliable's IQM (the mean of the middle three) over every one of the 5**5 resamples."""
    runs = [0.31, 0.9, 0.47, 0.66, 0.12]
    e = iqm([runs])
    dist = _resampled(runs, lambda d: np.sort(d)[1:4].mean())
    assert e.value == pytest.approx(np.mean(sorted(runs)[1:4]))
    _check_ends(dist, e.lo, e.hi, 0.95)


def test_the_interval_under_the_table_is_at_the_level_its_column_states():
    """What the table pages print under a table (`summary`, written verbatim into reports/<table>-<profile>.md): the
    level read from the column header ('[95% CI]') and the footer, the interval read from the printed cell (two
    decimals), checked at that level against the exact distribution of the two rows' runs. Table 2, Easy Aux SGN
    test: Dual-Attention's three runs beside GA's, no other row with runs."""
    da, ga = [0.9, 0.55, 0.72], [0.12, 0.6, 0.23]
    cells = [Cell("Dual-Attention", "easy", True, "sgn_test", 3, da), Cell("GA", "easy", True, "sgn_test", 3, ga)]
    rows, footer = summary(load_table("table2"), cells)
    line = next(r for r in rows if (r["Setting"], r["Model"]) == ("Easy · Aux", "GA"))
    (column,) = [k for k in line if k.startswith("SGN: Dual-Attention − row")]
    level = int(re.fullmatch(r"SGN: Dual-Attention − row \[(\d+)% CI\]", column).group(1)) / 100
    assert f"with its {level:.0%} percentile interval" in footer and f"{REPS:,} resamples" in footer
    value, lo, hi = map(float, re.fullmatch(r"(\S+) \[(\S+), (\S+)\] \(3 vs 3 runs in 1 cell\)", line[column]).groups())
    assert value == round(np.mean(da) - np.mean(ga), 2)
    _check_ends(_difference_distribution(da, ga), lo, hi, level, slack=0.005)
