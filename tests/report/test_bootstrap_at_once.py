"""The aggregate's and the field's stratified bootstrap, every resample at once (emml/report/aggregate.py
`stratified_bootstrap`), gives rliable's own intervals to the bit: the same draws from the same seeded generator,
the same statistic per resample, the same percentiles. rliable's loop (`rliable.library.get_interval_estimates`,
`create_performance_profile`) is run here as the reference, seeded as the report seeded it before."""

import warnings

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from rliable import library

from emml.report.aggregate import iqm, probability_of_improvement
from emml.report.field import TAUS, _profile

REPS = 60
"""Few resamples: rliable's loop is the slow side; the draws and percentiles are the same code at any count."""
SCORES = st.sampled_from([0.0, 0.25, 0.5, 0.75, 1.0]) | st.floats(0, 1)


def rliable_interval(scores, func, reps: int = REPS, seed: int = 0, profile: bool = False):
    """rliable's point and interval, its draws from NumPy's global generator seeded with ``seed`` (then restored)."""
    saved = np.random.get_state()
    np.random.seed(seed)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            if profile:
                points, intervals = library.create_performance_profile({"k": scores}, TAUS, reps=reps)
            else:
                points, intervals = library.get_interval_estimates(
                    {"k": scores}, func, reps=reps, random_state=np.random.RandomState(seed)
                )
    finally:
        np.random.set_state(saved)
    return points["k"], intervals["k"]


def cells_of(runs: int, cells: int):
    return st.lists(st.lists(SCORES, min_size=runs, max_size=runs), min_size=cells, max_size=cells)


@settings(max_examples=25, deadline=None)
@given(st.integers(2, 5).flatmap(lambda runs: st.integers(1, 3).flatmap(lambda cells: cells_of(runs, cells))))
def test_the_iqm_interval_is_rliables(cells):
    from rliable import metrics

    mine = iqm(cells, reps=REPS, seed=3)
    point, interval = rliable_interval(np.array(cells).T, lambda x: np.array([metrics.aggregate_iqm(x)]), seed=3)
    assert (mine.value, mine.lo, mine.hi) == (point[0], interval[0, 0], interval[1, 0])


@settings(max_examples=25, deadline=None)
@given(
    st.integers(1, 2).flatmap(
        lambda cells: st.tuples(
            st.integers(2, 4).flatmap(lambda runs: cells_of(runs, cells)),
            st.integers(2, 4).flatmap(lambda runs: cells_of(runs, cells)),
        )
    )
)
def test_the_probability_of_improvement_interval_is_rliables_with_equal_or_different_run_counts(xy):
    from rliable import metrics

    x, y = xy
    mine = probability_of_improvement(x, y, reps=REPS, seed=1)
    point, interval = rliable_interval(
        (np.array(x).T, np.array(y).T), lambda a, b: np.array([metrics.probability_of_improvement(a, b)]), seed=1
    )
    assert (mine.value, mine.lo, mine.hi) == (point[0], interval[0, 0], interval[1, 0])


@settings(max_examples=15, deadline=None)
@given(st.lists(SCORES, min_size=1, max_size=5))
def test_the_performance_profile_and_its_band_are_rliables(runs):
    matrix = np.array(runs, dtype=float)[:, None]
    profile, band = _profile(matrix, reps=REPS, seed=0)
    if len(runs) < 2:
        assert band is None and (profile == library.score_distributions(matrix, TAUS)).all()
        return
    point, interval = rliable_interval(matrix, None, profile=True)
    assert (profile == point).all() and (band == interval).all()


def test_the_global_generator_is_left_as_it_was():
    np.random.seed(7)
    before = np.random.get_state()[1].copy()
    iqm([[0.1, 0.5, 0.9]])
    assert (np.random.get_state()[1] == before).all()
