"""reports/index.md: what a reader should read first, and never smoke numbers."""

from emml.report.index import profiles_with_results


def test_quick_first_then_paper_then_the_rest_and_never_smoke(tmp_path):
    for table, profile in [("table2", "demo"), ("table2", "smoke"), ("table2", "paper"), ("table3", "quick")]:
        path = tmp_path / table / f"{profile}.csv"
        path.parent.mkdir(exist_ok=True)
        path.write_text("run_name\n")
    (tmp_path / "table2" / "quick.csv").write_text("run_name\n")
    assert profiles_with_results(tmp_path) == {"quick": ["table2", "table3"], "paper": ["table2"], "demo": ["table2"]}
