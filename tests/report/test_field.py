"""The rliable figure on a FIXTURE of made-up results in tmp_path (never results): a page wide, nothing cut, a row of
panels only where two rows or more have runs, the reference row emphasised."""

import matplotlib.pyplot as plt
import pandas as pd

from emml.config.profiles import profile_seeds
from emml.experiments.tables import load_table
from emml.report.cells import build_cells, paper_numbers, table_results
from emml.report.field import field_figure, plot_field
from emml.report.plan import plan_report
from emml.report.savefig import PAGE_INCHES, outside
from tests.report.test_tables import PROFILE, fake_results


def test_a_page_wide_nothing_cut_and_a_setting_with_one_row_left_out(tmp_path):
    table = load_table("table3")
    alone = [  # No Aux: DA Multi-Task alone (its runs are Table 2's), nothing to compare it with
        spec.run_name(PROFILE)
        for spec in table.runs(profile_seeds(PROFILE))
        if not spec.aux and spec.row != "DA Multi-Task"
    ]
    fake_results("table3", tmp_path / "results", drop=tuple(alone))
    plan = plan_report(table, PROFILE, tmp_path / "results")
    results = table_results(table, plan.profile, tmp_path / "results")
    assert not results[~results["aux"].astype(bool)].empty  # the No Aux DA runs are there, and not drawn
    fig = field_figure(table, plan.profile, build_cells(plan, results, paper_numbers("table3")))
    assert fig.get_size_inches()[0] == PAGE_INCHES
    assert outside(fig) == []
    titles = [ax.get_title() for ax in fig.axes if ax.get_title().endswith(": IQM")]
    assert titles == ["Easy · Aux · SGN test: IQM", "Easy · Aux · EQA test: IQM"]
    iqm = next(ax for ax in fig.axes if ax.get_title() == titles[0])
    bold = {t.get_text().split(" (")[0]: t.get_fontweight() for t in iqm.get_yticklabels()}
    assert bold["DA Multi-Task"] == "bold" and bold["w/o GA1"] == "normal"
    assert len(bold) == len(table.rows)
    plt.close(fig)


def test_no_figure_where_no_setting_has_two_rows(tmp_path):
    table = load_table("table3")
    only = [s.run_name(PROFILE) for s in table.runs(profile_seeds(PROFILE)) if s.row != "DA Multi-Task"]
    fake_results("table3", tmp_path / "results", drop=tuple(only))
    plan = plan_report(table, PROFILE, tmp_path / "results")
    results = table_results(table, plan.profile, tmp_path / "results")
    assert isinstance(results, pd.DataFrame) and not results.empty
    cells = build_cells(plan, results, paper_numbers("table3"))
    assert field_figure(table, plan.profile, cells) is None
    # an earlier report's figure of that name is removed, not left beside a page that no longer links it
    stale = [tmp_path / f"table3-{PROFILE}-rliable.png", tmp_path / f"table3-{PROFILE}-rliable.pdf"]
    other = tmp_path / f"table2-{PROFILE}-rliable.png"
    for p in (*stale, other):
        p.write_bytes(b"old")
    assert plot_field(table, plan.profile, cells, tmp_path) == []
    assert [p.exists() for p in (*stale, other)] == [False, False, True]


def test_the_rows_of_panels_are_packed_in_order_onto_pages_that_fit():
    """`pages`: rows of panels in the table's order, each page at most the limit with its title and legend
    (FRAME_INCHES 1.4); a row taller than a page alone is a page of its own."""
    from emml.report.field import FRAME_INCHES, pages

    assert FRAME_INCHES == 1.4
    assert pages([3.15] * 8, limit=9.0) == [[0, 1], [2, 3], [4, 5], [6, 7]]  # 1.4 + 6.3 = 7.7; a third: 10.85
    assert pages([2.0, 2.0, 2.0, 1.6, 3.0], limit=9.0) == [[0, 1, 2, 3], [4]]  # 1.4 + 7.6 = 9.0 exactly fits
    assert pages([2.0, 2.0, 2.0, 1.7], limit=9.0) == [[0, 1, 2], [3]]  # 9.1 does not
    assert pages([12.0, 1.0], limit=9.0) == [[0], [1]]  # too tall alone: a page of its own, not packed with more
    assert pages([]) == []


def test_every_page_is_written_and_a_page_an_earlier_report_left_is_removed(tmp_path, monkeypatch):
    import emml.report.field as field

    table = load_table("table2")
    fake_results("table2", tmp_path / "results")
    plan = plan_report(table, PROFILE, tmp_path / "results")
    cells = build_cells(plan, table_results(table, plan.profile, tmp_path / "results"), paper_numbers("table2"))
    stale = [tmp_path / f"table2-{PROFILE}-rliable-{k}.png" for k in (2, 9)]
    for p in stale:
        p.write_bytes(b"old")
    monkeypatch.setattr(field, "pages", lambda heights: [[0], list(range(1, len(heights)))])  # two pages
    paths = plot_field(table, plan.profile, cells, tmp_path)
    stem = f"table2-{PROFILE}-rliable"
    assert [p.name for p in paths] == [f"{stem}.png", f"{stem}.pdf", f"{stem}-2.png", f"{stem}-2.pdf"]
    assert all(p.stat().st_size > 1000 for p in paths)  # the page-2 figure, not the stale bytes
    assert not stale[1].exists()
