"""The rliable aggregate under a table: rliable's statistics, a seeded stratified bootstrap."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rliable import metrics

from emml.config.profiles import resolve_profile
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


# --- the rliable figure (emml/report/field.py): read from the figure's artists, never its file size -------------------
def _field(values: dict, paper: dict | None = None, table: str = "table2"):
    """FIXTURE: the figure of made-up cells: ``values`` {(row, difficulty, aux, metric): runs' scores}."""
    from emml.report.cells import Cell
    from emml.report.field import field_figure

    t = load_table(table)
    cells = [
        Cell(row, d, a, m, 3, values=list(v), paper=(paper or {}).get((row, d, a, m)))
        for (row, d, a, m), v in values.items()
    ]
    return field_figure(t, resolve_profile("quick"), cells)


FIELD = {
    ("Dual-Attention", "easy", True, "sgn_test"): [0.90, 0.92, 0.94],
    ("Dual-Attention", "easy", True, "eqa_test"): [0.30, 0.40, 0.50],
    ("Concat", "easy", True, "sgn_test"): [0.30],
    ("Concat", "easy", True, "eqa_test"): [0.20],
}
PAPER = {("Dual-Attention", "easy", True, "sgn_test"): "0.96", ("Concat", "easy", True, "sgn_test"): "0.31"}


def _lines(ax, prefix: str) -> dict[str, list]:
    """The axes' series whose label starts with ``prefix`` ('_point', '_ci', '_single', '_paper'), by row."""
    return {ln.get_label().split(" ", 1)[1]: ln for ln in ax.get_lines() if ln.get_label().startswith(prefix + " ")}


def test_the_figure_keeps_sgn_and_eqa_apart_a_panel_row_each():
    """Issue 60: the IQM panel pooled SGN and EQA into one number per row (DA Easy·Aux 0.70 beside 0.92 / 0.44)."""
    import matplotlib.pyplot as plt

    fig = _field(FIELD, PAPER)
    axes = np.array(fig.axes[:6]).reshape(2, 3)
    assert [ax.get_title() for ax in axes[:, 0]] == [
        "Easy · Aux · SGN test: IQM",
        "Easy · Aux · EQA test: IQM",
    ]
    for ax, metric in zip(axes, ("SGN test", "EQA test")):
        other = "EQA" if metric.startswith("SGN") else "SGN"
        assert metric in ax[0].get_title()  # the row's first panel names its one metric
        for panel in ax:  # and no panel of the row names the other
            assert other not in panel.get_xlabel() + panel.get_title()
    sgn, eqa = (_lines(axes[i, 0], "_point")["Dual-Attention"].get_xdata()[0] for i in (0, 1))
    assert sgn == pytest.approx(0.92) and eqa == pytest.approx(0.40)  # each its own cell's IQM: nothing pooled
    plt.close(fig)


def test_single_runs_are_points_without_intervals_and_n_counts_runs():
    import matplotlib.pyplot as plt

    fig = _field(FIELD, PAPER)
    iqm_ax, p_ax, profile_ax = fig.axes[:3]
    assert set(_lines(iqm_ax, "_ci")) == {"Dual-Attention"}  # 3 runs: an interval
    lo, hi = _lines(iqm_ax, "_ci")["Dual-Attention"].get_xdata()
    assert lo < 0.92 < hi
    single = _lines(iqm_ax, "_single")
    assert set(single) == {"Concat"} and single["Concat"].get_xdata()[0] == pytest.approx(0.30)
    assert single["Concat"].get_markerfacecolor() in ("white", (1.0, 1.0, 1.0, 1.0))  # hollow: one run
    # (n): the runs in the cell, as the title says; 3, not 3 runs × 2 metrics
    assert [t.get_text() for t in iqm_ax.get_yticklabels()] == ["Dual-Attention (3)", "Concat (1)"]
    # P(DA > Concat) with one Concat run: a point, no interval; n as runs on each side
    assert set(_lines(p_ax, "_single")) == {"Concat"} and not _lines(p_ax, "_ci")
    assert _lines(p_ax, "_single")["Concat"].get_xdata()[0] == 1.0
    assert [t.get_text() for t in p_ax.get_yticklabels()] == ["Concat (3 vs 1)"]
    assert "(n) = runs\nin the cell" in fig._suptitle.get_text()
    legend = [t.get_text() for t in fig.legends[0].get_texts()]  # one legend for the figure, under it
    assert legend[:2] == ["Concat", "Dual-Attention"] and "one run: no interval" in legend
    plt.close(fig)


def test_the_papers_number_is_drawn_where_the_paper_has_one():
    import matplotlib.pyplot as plt

    fig = _field(FIELD, PAPER)
    sgn, eqa = fig.axes[0], fig.axes[3]
    marks = _lines(sgn, "_paper")
    assert {row: ln.get_xdata()[0] for row, ln in marks.items()} == {"Dual-Attention": 0.96, "Concat": 0.31}
    y = {row: ln.get_ydata()[0] for row, ln in marks.items()}  # on its row
    assert y == {row: ln.get_ydata()[0] for row, ln in _lines(sgn, "_point").items() | _lines(sgn, "_single").items()}
    assert not _lines(eqa, "_paper")  # no paper number given for EQA here: none drawn
    assert "the paper's number" in [t.get_text() for t in fig.legends[0].get_texts()]
    plt.close(fig)


def test_the_title_and_every_label_fit_inside_the_figure():
    """Issue 60: the title was cut at both edges."""
    import matplotlib.pyplot as plt

    values = {**FIELD, **{(r.label, "hard", False, "eqa_test"): [0.3, 0.35] for r in load_table("table2").rows}}
    fig = _field(values, PAPER)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    box = fig.bbox
    texts = [fig._suptitle, *fig.legends[0].get_texts()]
    for ax in fig.axes:
        texts += [ax.title, ax.xaxis.label, ax.yaxis.label, *ax.get_yticklabels(), *ax.get_xticklabels()]
        if ax.get_legend() is not None:
            texts += ax.get_legend().get_texts()
    assert "table2 [quick]" in fig._suptitle.get_text() and "per setting and metric" in fig._suptitle.get_text()
    for t in texts:
        if not t.get_text() or not t.get_visible():
            continue
        e = t.get_window_extent(renderer)
        assert box.x0 - 0.5 <= e.x0 and e.x1 <= box.x1 + 0.5 and box.y0 - 0.5 <= e.y0 and e.y1 <= box.y1 + 0.5, (
            t.get_text()
        )
    assert len(fig.axes) == 3 * 3  # Easy·Aux SGN, Easy·Aux EQA, Hard·No Aux EQA: no empty panel
    plt.close(fig)


def test_no_figure_for_a_transfer_table_or_without_runs():
    assert _field({}) is None
    assert _field({("Text only", "easy", True, "sgn_test"): [0.2]}, table="table4") is None
