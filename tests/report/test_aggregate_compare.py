"""The aggregate under a table (emml/report/aggregate.py: `compare`, `summary`) on cells made by hand: which rows are
compared, when an interval is given, and the lines as the page prints them. Written against the survivors of
`make mutate MUTATE=report/aggregate` (docs/testing.md); every expected value below is worked out from the rule."""

import dataclasses

import pytest

from emml.experiments.tables import load_table
from emml.report.aggregate import Estimate, _show, compare, probability_of_improvement, summary
from emml.report.cells import Cell

DA, CONCAT, GA = "Dual-Attention", "Concat", "GA"
SGN, EQA = "sgn_test", "eqa_test"


def _cells(values: dict) -> list[Cell]:
    """Only the cells given ({(row, difficulty, aux, metric): runs' scores}): a cell not listed does not exist."""
    return [Cell(row, d, a, m, 3, values=list(v)) for (row, d, a, m), v in values.items()]


def _by_row(found, metric: str = SGN) -> dict:
    return {c.row: c for c in found if (c.difficulty, c.aux, c.metric) == ("easy", True, metric)}


def test_one_run_on_either_side_gives_p_without_an_interval_and_two_on_both_sides_with_one():
    """P(DA > row) from 2 runs against 1 (or 1 against 2) is a single number: Estimate(p, p, p, runs, 1 cell, no
    spread); 2 against 2 keeps the resampled interval."""
    table = load_table("table2")
    da = [0.9, 0.7]
    found = _by_row(compare(table, _cells({(DA, "easy", True, SGN): da, (CONCAT, "easy", True, SGN): [0.8],
                                           (GA, "easy", True, SGN): [0.6, 0.8]})))  # fmt: skip
    # 2 vs 1: 0.9 > 0.8, 0.7 < 0.8: P = 1/2, three scores read, in one cell, nothing to resample
    assert found[CONCAT].improvement == Estimate(0.5, 0.5, 0.5, 3, 1, False)
    # 2 vs 2: pairs 0.9>0.6, 0.9>0.8, 0.7>0.6, 0.7<0.8 -> 3/4, with its interval from the resampling
    ga = found[GA].improvement
    assert ga == probability_of_improvement([da], [[0.6, 0.8]]) and ga.value == 0.75 and ga.spread
    assert ga.lo < ga.value and ga.hi == 1.0 and ga.runs == 4 and ga.cells == 1
    assert found[GA].reference_runs == 2 and found[CONCAT].reference_runs == 2
    # 1 vs 2, the other way round: still one number
    one = _by_row(compare(table, _cells({(DA, "easy", True, SGN): [0.9], (GA, "easy", True, SGN): [0.6, 0.95]})))
    assert one[GA].improvement == Estimate(0.5, 0.5, 0.5, 3, 1, False)


def test_a_cell_with_no_reference_run_and_a_row_with_no_cell_are_not_compared():
    """Where Dual-Attention has no cell in a setting, the rows there get their IQM and no comparison; a row with no
    cell in a setting is left out of it."""
    table = load_table("table2")
    found = compare(table, _cells({(CONCAT, "easy", True, SGN): [0.2, 0.4], (DA, "easy", True, EQA): [0.5]}))
    assert [(c.row, c.metric) for c in found] == [(CONCAT, SGN), (DA, EQA)]
    concat = found[0]
    assert concat.reference_runs == 0 and concat.difference is None and concat.improvement is None
    assert concat.iqm.value == pytest.approx(0.3) and concat.iqm.runs == 2


def test_an_interval_is_signed_only_when_its_value_is():
    e = Estimate(0.5, 0.4, 0.6, 3, 1, True)
    assert _show(e, "3 runs") == "0.50 [0.40, 0.60] (3 runs)"
    assert _show(e, "3 runs", signed=True) == "+0.50 [+0.40, +0.60] (3 runs)"
    assert _show(dataclasses.replace(e, spread=False), "1 run") == "0.50 (1 run: no interval)"


def test_no_aggregate_without_a_run():
    table = load_table("table2")
    assert summary(table, _cells({(DA, "easy", True, SGN): [], (CONCAT, "easy", True, SGN): []})) is None


def test_the_lines_put_each_metric_s_three_columns_together_in_the_table_s_order():
    """SGN's IQM, difference and P, then EQA's (the table's metric order, not the alphabet's); a row where
    Dual-Attention has no run says so in both comparison columns; Dual-Attention's own comparison cells are blank."""
    table = load_table("table2")
    rows, _ = summary(table, _cells({(DA, "easy", True, SGN): [0.9], (CONCAT, "easy", True, SGN): [0.3],
                                     (CONCAT, "easy", True, EQA): [0.4]}))  # fmt: skip
    assert list(rows[0]) == [
        "Setting",
        "Model",
        "SGN IQM [95% CI]",
        "SGN: Dual-Attention − row [95% CI]",
        "SGN: P(Dual-Attention > row)",
        "EQA IQM [95% CI]",
        "EQA: Dual-Attention − row [95% CI]",
        "EQA: P(Dual-Attention > row)",
    ]
    concat, da = rows  # in the table's row order
    assert da["Model"] == DA and da["SGN: P(Dual-Attention > row)"] == "" and da["EQA IQM [95% CI]"] == ""
    assert concat["SGN: Dual-Attention − row [95% CI]"] == "+0.60 (1 vs 1 run in 1 cell: no interval)"
    assert concat["EQA: Dual-Attention − row [95% CI]"] == "— (Dual-Attention: no run here)"
    assert concat["EQA: P(Dual-Attention > row)"] == "— (Dual-Attention: no run here)"
    assert concat["EQA IQM [95% CI]"] == "0.40 (1 run in 1 cell: no interval)"


def test_a_table_without_a_reference_row_still_lists_every_metric_of_every_row():
    """No Dual-Attention row (a table of one's own): each row's IQM per metric, no comparison columns."""
    table = load_table("table2")
    table = dataclasses.replace(table, rows=tuple(r for r in table.rows if r.label != DA))
    rows, footer = summary(table, _cells({(CONCAT, "easy", True, SGN): [0.3], (CONCAT, "easy", True, EQA): [0.4],
                                          (GA, "easy", True, SGN): [0.5]}))  # fmt: skip
    assert [list(r) for r in rows] == [["Setting", "Model", "SGN IQM [95% CI]", "EQA IQM [95% CI]"]] * 2
    assert [(r["Model"], r["SGN IQM [95% CI]"][:4], r["EQA IQM [95% CI]"][:4]) for r in rows] == [
        (CONCAT, "0.30", "0.40"),
        (GA, "0.50", ""),
    ]
    assert "P(" not in footer


COMMON = (
    "Aggregate per setting (difficulty × aux: Aux and No Aux apart, Easy and Hard apart) and metric, so that rows "
    "compare like with like: each number reads one cell of the table above, over the runs (seeds) it holds, and a row "
    "with no run in a setting is not compared there; runs and cells are counted apart. IQM = the interquartile mean "
    "of a row's runs (rliable.metrics.aggregate_iqm; Agarwal et al. 2021; with 3 runs or fewer it is their mean), "
    "with a 95% bootstrap percentile interval (the cell's runs resampled with replacement, 2,000 resamples, seed 0)."
)
COMPARED = (
    " Dual-Attention − row = the difference of the two rows' means in that cell, with its 95% percentile interval "
    "from resampling each row's runs with replacement (2,000 resamples, seed 0); P(Dual-Attention > row) = the "
    "probability that a run of Dual-Attention scores higher than a run of the row in the same cell (ties count half; "
    "rliable.metrics.probability_of_improvement), with its 95% interval from the same resampling "
    "(rliable.library.get_interval_estimates). Read the difference beside the probability: P = 1.00 says every run "
    "is ahead, not by how much."
)
TAIL = (
    " Where a row has one run in the cell, resampling has nothing to move: no interval is given, and the number is "
    "one seed's. With three seeds or fewer the intervals are wide: read them, not the point alone; whether a claim "
    "holds is decided on the claims page (claims-<profile>.md) against the evaluation's binomial error."
)


def test_the_footer_says_what_each_number_is_and_names_no_comparison_without_a_reference_row():
    """The footer under the aggregate as the page prints it, word for word: what it compares, with what resampling;
    without a reference row (a table of one's own) the comparisons' sentences are left out."""
    table = load_table("table2")
    assert summary(table, _cells({(CONCAT, "easy", True, SGN): [0.3]}))[1] == COMMON + COMPARED + TAIL
    alone = dataclasses.replace(table, rows=tuple(r for r in table.rows if r.label != DA))
    assert summary(alone, _cells({(CONCAT, "easy", True, SGN): [0.3]}))[1] == COMMON + TAIL


def test_the_mean_difference_has_an_interval_only_with_two_runs_on_each_side():
    """mean(x) − mean(y) in one cell: a single number while either side has one run, the resampled interval from two
    runs on each side (the values chosen to be exact in binary)."""
    from emml.report.aggregate import mean_difference

    assert mean_difference([0.75, 0.25], [0.5]) == Estimate(0.0, 0.0, 0.0, 3, 1, False)
    assert mean_difference([0.5], [0.75, 0.25]) == Estimate(0.0, 0.0, 0.0, 3, 1, False)
    e = mean_difference([0.75, 0.25], [0.5, 0.0])
    assert e.value == 0.25 and e.spread and e.lo < 0.25 < e.hi and (e.runs, e.cells) == (4, 1)
    # each extreme (x resampled to its worst twice, y to its best, and back) has 1/16 > 2.5% of the resamples
    assert (e.lo, e.hi) == (-0.25, 0.75)
    x, y = [0.9, 0.7, 0.4, 0.65], [0.3, 0.55, 0.1]
    assert mean_difference(x, y) == mean_difference(x, y)  # seeded: the same interval every time it is drawn
    assert mean_difference(x, y, seed=1) != mean_difference(x, y)  # and the draws are the seed's


def test_an_iqm_has_an_interval_from_two_runs_a_cell():
    """Two runs in a cell are enough to resample: each resample is both at 0.25, both at 0.75 (1/4 each, > 2.5%) or
    one of each, so the 95% interval runs from 0.25 to 0.75 around the IQM of the two (their mean, 0.5). One run: the
    point alone."""
    from emml.report.aggregate import iqm

    assert iqm([[0.25, 0.75]]) == Estimate(0.5, 0.25, 0.75, 2, 1, True)
    assert iqm([[0.25], [0.75]]) == Estimate(0.5, 0.5, 0.5, 2, 2, False)


def test_p_of_improvement_has_an_interval_when_either_row_has_two_runs_in_a_cell():
    """Called alone (compare masks it when a side has one run): x = (0.25, 0.75) against y = 0.5, one cell. Each
    resample of x is both low (P = 0), both high (P = 1), 1/4 each (> 2.5%), or one of each (0.5): the interval is
    [0, 1] around 0.5, whichever side has the two runs; one run a side: the point alone."""
    two, one = [[0.25, 0.75]], [[0.5]]
    assert probability_of_improvement(two, one) == Estimate(0.5, 0.0, 1.0, 3, 1, True)
    assert probability_of_improvement(one, two) == Estimate(0.5, 0.0, 1.0, 3, 1, True)
    assert probability_of_improvement(one, [[0.25]]) == Estimate(1.0, 1.0, 1.0, 2, 1, False)
