"""reports/index.md: what a reader should read first, the experiments beyond the paper after its tables, and never
smoke numbers."""

from emml.experiments.tables import load_table
from emml.report.index import profiles_with_results


def test_quick_first_then_paper_then_the_rest_and_never_smoke(tmp_path):
    for table, profile in [("table2", "demo"), ("table2", "smoke"), ("table2", "paper"), ("table3", "quick")]:
        path = tmp_path / table / f"{profile}.csv"
        path.parent.mkdir(exist_ok=True)
        path.write_text("run_name\n")
    (tmp_path / "table2" / "quick.csv").write_text("run_name\n")
    for folder in ("eqa_readout", "mine"):  # issue 34's experiment is reported after the paper's tables; not a stray
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "quick.csv").write_text("run_name\n")
    assert profiles_with_results(tmp_path) == {
        "quick": ["table2", "table3", "eqa_readout"],
        "paper": ["table2"],
        "demo": ["table2"],
    }
    assert load_table("eqa_readout").rows[1].label == "mean"  # loadable by its name from here on
