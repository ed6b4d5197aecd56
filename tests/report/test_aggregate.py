"""The rliable aggregate under a table: rliable's statistics, a seeded stratified bootstrap."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rliable import metrics

from emml.experiments.tables import load_table
from emml.report.aggregate import improvement, interquartile_mean, iqm, probability_of_improvement, reference_row

CELLS = [[0.92, 0.89, 0.93], [0.1, 0.4, 0.2], [0.5, 0.6, 0.7]]


def test_iqm_is_rliables_and_its_interval_holds_it_and_repeats_to_the_digit():
    e = iqm(CELLS)
    assert e.value == pytest.approx(metrics.aggregate_iqm(np.array(CELLS).T))
    assert e.lo <= e.value <= e.hi and (e.runs, e.cells, e.spread) == (9, 3, True)
    assert iqm(CELLS) == e
    assert iqm(CELLS, reps=40, seed=1) != iqm(CELLS, reps=40)  # the interval comes from the seeded resampling
    np.random.seed(5)
    assert iqm(CELLS) == e  # whatever the global generator holds


def test_cells_with_more_seeds_than_the_fewest_are_read_on_their_first_seeds():
    assert iqm([[0.9, 0.8, 0.1], [0.3, 0.5]]) == iqm([[0.9, 0.8], [0.3, 0.5]])


def test_one_run_per_cell_has_nothing_to_resample():
    e = iqm([[0.3], [0.5]])
    assert (e.value, e.lo, e.hi, e.spread) == (0.4, 0.4, 0.4, False)


def test_probability_of_improvement_is_rliables_over_the_common_cells():
    x, y = [[0.9, 0.8], [0.3, 0.5], [0.7, 0.7]], [[0.1, 0.85], [0.4, 0.4], []]
    e = probability_of_improvement(x, y)
    assert e.value == pytest.approx(metrics.probability_of_improvement(np.array(x[:2]).T, np.array(y[:2]).T))
    assert e.value == pytest.approx((3 / 4 + 1 / 2) / 2)  # cell by cell, then averaged
    assert 0 <= e.lo <= e.value <= e.hi <= 1 and e.cells == 2
    assert probability_of_improvement([[0.2]], [[0.2]]).value == 0.5  # a tie counts half
    assert probability_of_improvement([[0.2], []], [[], [0.3]]) is None  # no cell in common


def test_the_reference_row_is_the_papers_dual_attention():
    assert reference_row(load_table("table2")) == "Dual-Attention"
    assert reference_row(load_table("table3")) == "DA Multi-Task"
    assert reference_row(load_table("table4")) is None  # every row reads the same transfer runs


@settings(max_examples=200, deadline=None)
@given(
    st.integers(1, 4).flatmap(
        lambda cells: st.tuples(
            st.lists(st.lists(st.sampled_from([0.0, 0.25, 0.5, 0.75, 1.0]) | st.floats(0, 1), min_size=cells,
                              max_size=cells), min_size=1, max_size=4),
            st.lists(st.lists(st.sampled_from([0.0, 0.25, 0.5, 0.75, 1.0]) | st.floats(0, 1), min_size=cells,
                              max_size=cells), min_size=1, max_size=4),
        )
    )
)  # fmt: skip
def test_the_vectorised_improvement_is_rliables_to_the_bit(xy):
    """Ties included (scores on a grid of episodes repeat): the same number as rliable's scipy-based statistic."""
    x, y = np.array(xy[0]), np.array(xy[1])
    assert improvement(x, y) == metrics.probability_of_improvement(x, y)


@settings(max_examples=300, deadline=None)
@given(
    st.integers(1, 7).flatmap(
        lambda runs: st.lists(
            st.lists(st.sampled_from([0.0, 0.25, 0.5, 0.75, 1.0]) | st.floats(0, 1), min_size=runs, max_size=runs),
            min_size=1,
            max_size=5,
        )
    )
)
def test_the_interquartile_mean_is_rliables_to_the_bit(cells):
    """Runs × cells, ties included: the same float as rliable's scipy-based aggregate_iqm."""
    scores = np.array(cells).T
    assert interquartile_mean(scores) == metrics.aggregate_iqm(scores)
