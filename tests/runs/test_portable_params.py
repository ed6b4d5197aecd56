"""Issue 63, item 5: the store holds a run's roots by their names (``runs``, ``results``), never a path of the
machine that trained it or imported its run dir, whether the tracker logs them (training) or `emml import-runs`
makes the run of a committed run dir."""

import json
import shutil

import pytest
from typer.testing import CliRunner

from emml.config.paths import checkout_root
from emml.runs import import_runs as importer
from emml.runs import store
from emml.runs.portable import OUTSIDE, root_name
from emml.runs.tracking import Tracker, flatten
from tests.runs.test_import_runs import CONFIG, write_run

ROOTS = ("run_root", "results_root")


@pytest.fixture(autouse=True)
def _store(tmp_path, monkeypatch):
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path / 'store' / 'mlflow.db'}")
    monkeypatch.setenv("MLFLOW_DISABLE_TELEMETRY", "true")


def test_a_root_is_named_as_in_its_checkout_on_every_machine():
    here = checkout_root()
    assert root_name(str(here / "runs"), "runs") == "runs"
    assert root_name(str(here / "runs" / "extended"), "runs") == "runs/extended"
    assert root_name("runs/noaux_arms", "runs") == "runs/noaux_arms"
    assert root_name("/work/main/runs", "runs") == "runs"  # another machine's checkout
    assert root_name("/work/main/results", "results") == "results"
    assert root_name("/home/me/emml/scratch/runs", "runs") == "scratch/runs"  # the smoke profile's
    assert root_name("/srv/runs/emml/runs/extended", "runs") == "runs/extended"  # the last runs/ is the checkout's
    assert root_name("/tmp/ext-results", "results") == f"ext-results{OUTSIDE}"  # no path of the machine
    assert root_name("../elsewhere/results", "results") == "results"


def test_the_tracker_logs_the_roots_by_name(tmp_path):
    cfg = {**CONFIG, "run_root": "/work/main/runs", "results_root": str(tmp_path / "scratch" / "results")}
    assert {k: flatten(cfg)[k] for k in ROOTS} == {"run_root": "runs", "results_root": "scratch/results"}
    tracker = Tracker()
    run_id = tracker.start("roots", "trained", {"seed": 3}, cfg)
    tracker.finish()
    params = store.client().get_run(run_id).data.params
    assert {k: params[k] for k in ROOTS} == {"run_root": "runs", "results_root": "scratch/results"}
    assert params["model"] == "dual_attention"  # the other params as they were


def committed_samples(dest):
    """A copy, under ``dest``/runs, of one committed run dir per kind of roots its config names (another machine's
    checkout, a folder under runs/, a temporary results folder): their points left out (the params are the point)."""
    seen, out = set(), []
    for results in sorted((checkout_root() / "runs").glob("**/results.json")):
        config = json.loads(results.read_text()).get("config") or {}
        kind = tuple(str(config.get(k, "")).startswith("/") for k in ROOTS) + ("/" in config.get("run_root", ""),)
        if kind in seen:
            continue
        seen.add(kind)
        copy = dest / "runs" / results.parent.relative_to(checkout_root() / "runs")
        copy.mkdir(parents=True)
        shutil.copy(results, copy / "results.json")
        (copy / "metrics.csv").write_text("step,key,value\n")
        out.append((copy, config))
    return out


def test_an_import_of_committed_runs_names_no_folder_outside_runs_and_results(tmp_path):
    samples = committed_samples(tmp_path)
    own = {str(c[k]) for _, c in samples for k in ROOTS}
    assert any(v.startswith("/work/") for v in own) and "runs/extended" in own  # each kind of root is tried
    results = importer.import_runs([tmp_path / "runs"])
    assert [r.outcome for r in results] == ["imported"] * len(samples), [r.line() for r in results]
    for result, (run_dir, config) in zip(results, samples):
        params = store.client().get_run(result.mlflow_run_id).data.params
        assert params["run_root"] == str(run_dir.parent.parent.relative_to(tmp_path)), params["run_root"]
        if str(config["results_root"]).startswith("/tmp/"):  # its row went to a throwaway folder: said, not named
            assert params["results_root"] == f"{config['results_root'].rsplit('/', 1)[-1]}{OUTSIDE}"
        else:
            assert params["results_root"] == "results"
        assert not [f"{k}={v}" for k, v in params.items() if v.startswith(("/", "..")) or "/../" in v]


def test_a_moved_run_dir_is_named_by_the_root_it_is_in(tmp_path):
    """A run dir copied to another root (runs/extended, to train it further) names the root it is in, not the one its
    config recorded."""
    trained = write_run(tmp_path, "moved", "r", "e" * 32, config={**CONFIG, "run_root": "/work/main/runs"})
    run = tmp_path / "runs" / "extended" / "moved" / "r"
    run.parent.mkdir(parents=True)
    trained.rename(run)
    [result] = importer.import_runs([run])
    assert store.client().get_run(result.mlflow_run_id).data.params["run_root"] == "runs/extended"


def test_import_runs_takes_the_run_and_results_roots(tmp_path):
    from emml.cli import app

    write_run(tmp_path, "roots-cli", "r", "d" * 32, config={**CONFIG, "results_root": "/work/main/results"})
    missing = CliRunner().invoke(app, ["import-runs", "--run-root", str(tmp_path / "nowhere")])
    assert missing.exit_code == 2, missing.output
    assert f"no such run dir or folder: {tmp_path / 'nowhere'} (--run-root)" in missing.output
    out = CliRunner().invoke(
        app, ["import-runs", "--run-root", str(tmp_path / "runs"), "--results-root", "results/alt", "--json"]
    )
    assert out.exit_code == 0, out.output
    assert json.loads(out.stdout)["imported"] == 1
    [run] = store.find_runs("roots-cli")
    assert run["params"]["results_root"] == "results/alt"  # its rows are there in this checkout
