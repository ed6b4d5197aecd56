"""The table pages a reader takes in at a glance (issue 49) on a FIXTURE of made-up results and run dirs in tmp_path
(never results): a headline and the figures first, the rliable figures written with TrueType fonts, and `emml reports`
twice the same bytes (the `.tex`: tests/report/test_tex.py)."""

from emml.report.index import write_reports
from emml.report.tables import report_table
from tests.report.test_efficiency import write_curves
from tests.report.test_tables import PROFILE, fake_results, fake_run_dirs


def pages(tmp_path, tables=("table2", "table3")) -> list[dict]:
    for table in tables:
        fake_results(table, tmp_path / "results")
        fake_run_dirs(table, tmp_path / "runs")
        write_curves(tmp_path / "runs", table, lambda s: 0.5)
    kw = dict(results_root=tmp_path / "results", out=tmp_path / "reports", run_root=tmp_path / "runs")
    return [report_table(table, PROFILE, **kw) for table in tables]


def test_a_page_opens_with_its_headline_and_figures_and_lists_the_crossings(tmp_path):
    (data,) = pages(tmp_path, ("table3",))
    text = (tmp_path / "reports" / "table3-quick.md").read_text()
    head = text.split("\n")
    assert head[2].startswith("**In one line** (quick; 3–5 seeds per cell): Easy · No Aux: SGN test DA Multi-Task")
    assert "![table3-quick-rliable](table3-quick-rliable.png)" in text[: text.index("Ours vs the paper")]
    assert "### Sample efficiency" in text and "0.75M / 0.75M / 0.75M" in text  # 0.5 of 1.5M frames
    pdf = (tmp_path / "reports" / "table3-quick-rliable.pdf").read_bytes()
    assert b"/Type3" not in pdf and b"/CIDFontType2" in pdf  # TrueType (Type 42): emml/report/emml.mplstyle
    assert {p.rsplit("/", 1)[1] for p in data["paths"]} >= {"table3-quick-rliable.png", "table3-quick-rliable.pdf"}


def test_emml_reports_twice_changes_no_byte(tracking, tmp_path):
    for table in ("table2", "table3"):
        fake_results(table, tmp_path / "results")
        fake_run_dirs(table, tmp_path / "runs")
        write_curves(tmp_path / "runs", table, lambda s: 0.5)
    kw = dict(results_root=tmp_path / "results", run_root=tmp_path / "runs", log=lambda _: None)
    write_reports(tmp_path / "reports", **kw)
    first = {p.name: p.read_bytes() for p in sorted((tmp_path / "reports").iterdir())}
    assert {"index.md", "claims-quick.md", "table2-quick-rliable.pdf", "table3-quick-curves.png"} <= set(first)
    write_reports(tmp_path / "reports", **kw)
    assert {p.name: p.read_bytes() for p in sorted((tmp_path / "reports").iterdir())} == first
