"""`emml report` and `emml reports` read the runs and results rows under the roots they are given (issue 63:
`--run-root`, `--results-root`, defaults the profile's), and a report made with a plugin says so in its "Made by"
line (issue 64: `report ./my_table.toml` needs the `--plugin` its models come from)."""

import json

from typer.testing import CliRunner

from emml.cli import app
from tests.report.test_tables import fake_results

runner = CliRunner()


def test_report_reads_the_roots_it_is_given_and_names_its_plugins(tmp_path, monkeypatch):
    import emml.models.plugins

    fake_results("table3", tmp_path / "results", value=lambda spec: 0.25)  # no committed row holds 0.25 everywhere
    plugin = tmp_path / "mine" / "toy_fusion.py"  # the plugins this process was started with (`emml --plugin`)
    monkeypatch.setattr(emml.models.plugins, "configured", lambda: [str(plugin), "my_pkg.models"])
    monkeypatch.setattr(emml.models.plugins, "load_plugins", lambda: None)  # named, not loaded: the models are emml's
    args = ["report", "table3", "--profile", "quick", "--no-curves", "--json", "--out", str(tmp_path / "reports")]
    args += ["--results-root", str(tmp_path / "results"), "--run-root", str(tmp_path / "runs")]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["results"] == str(tmp_path / "results" / "table3" / "quick.csv")
    ours = [v for c in data["cells"] for v in c["values"]]
    assert ours and set(ours) == {0.25}  # the rows of the results root given, not the checkout's results/
    assert "no run dir here" in data["deviations"]["sources"]  # the run root given holds no run dir
    made = f"emml --plugin {plugin} --plugin my_pkg.models"
    assert f"Made by `{made} run table3 --profile quick` and `{made} report table3 --profile quick`." in data["caption"]


def test_reports_pass_their_roots_to_every_page(tmp_path, monkeypatch):
    import emml.cli.reports
    import emml.report.index

    seen = {}

    def write_reports(out=None, **kw):
        seen.update(kw, out=out)
        return tmp_path / "index.md"

    monkeypatch.setattr(emml.report.index, "write_reports", write_reports)
    monkeypatch.setattr(emml.cli.reports, "_check_store", lambda: None)
    monkeypatch.setattr(emml.cli.reports, "_own_engines", lambda: None)
    args = ["reports", "--out", str(tmp_path), "--results-root", "elsewhere/results", "--run-root", "elsewhere/runs"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert (seen["results_root"], seen["run_root"]) == ("elsewhere/results", "elsewhere/runs")
    seen.clear()
    assert runner.invoke(app, ["reports", "--out", str(tmp_path)]).exit_code == 0
    assert "results_root" not in seen and "run_root" not in seen  # write_reports' defaults: results/, runs/
