"""Issue 53, item 1: a run's MLflow record as its users expect: when it trained (recorded by the trainer, kept on
import, estimated for a run dir from before), its commit as the Source, its experiment's description, a unique name,
its final score apart from the periodic evaluations, and no absolute path of the machine in a param or tag."""

import json
import os
import re
import subprocess

from emml.config import paths
from emml.config.paths import project_root
from emml.config.profiles import profile_config
from emml.rl.trainer import train
from emml.runs import mirror, portable, provenance, store
from emml.runs.import_runs import TIMES, commit_times, import_run_dir, run_times
from emml.runs.results import read_results
from emml.runs.rundir import METRICS, RESULTS, results_csv, utc_ms
from emml.runs.tracking import display_name
from tests.runs.test_import_runs import write_run


def no_machine_path(values: dict, *folders) -> list[str]:
    """The values that hold an absolute path: one of ``folders`` (not as the end of a relative path, '../../tmp/x'),
    or any other (emml.runs.portable.portable would rewrite them)."""
    absolute = [re.compile(r"(?<![\w.])" + re.escape(str(f))) for f in folders]
    return [f"{k}={v}" for k, v in values.items() if portable.portable(v) != v or any(a.search(v) for a in absolute)]


def test_a_trained_run_records_when_it_trained_and_its_import_keeps_it(tmp_path, monkeypatch, no_leftovers):
    uri = f"sqlite:///{tmp_path}/trained.db"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    roots = {"run_root": str(tmp_path / "runs"), "results_root": str(tmp_path / "results")}  # absolute
    cfg = profile_config("smoke", "easy", {**roots, "table": "table2", "frames": 64, "final_eval_episodes": 1})
    result = train(cfg, quiet=True)
    record = json.loads((result.run_dir / RESULTS).read_text())
    start, end = utc_ms(record["started_at"]), utc_ms(record["ended_at"])
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\+00:00", record["started_at"]) and start <= end
    assert not {"started_at", "ended_at"} & set(read_results(results_csv(cfg)).columns)  # results.json only
    [run] = store.find_runs("table2")
    info = store.client(uri).get_run(run["run_id"]).info
    assert abs(info.start_time - start) < 5_000 and info.end_time >= end - 1_000
    tags, params = run["tags"], run["params"]
    assert tags["trained_frames"] == "64" and tags["score_eval_episodes"] == "1"
    assert tags[provenance.GIT_COMMIT] == provenance.full_commit(tags["git_sha"])
    assert (params["run_root"], params["results_root"]) == ("runs", "results")  # by name: no path of the machine
    assert no_machine_path(tags | params, tmp_path, project_root()) == []
    finals = sorted(k for k in run["metrics"] if k.startswith("final/"))
    assert finals == [f"final/{k}" for k in sorted(record["metrics"])]  # the score, apart from eval/*
    assert store.metric_history(run["run_id"], "final/sgn_test") == [(64, record["metrics"]["sgn_test"])]
    assert any(k.startswith("final/") for _, k, _ in mirror.read_mirror(result.run_dir / METRICS))
    exp = store.client(uri).get_experiment_by_name("table2")
    assert exp.tags[provenance.NOTE].startswith("Accuracy of all models on SGN & EQA test sets")

    other = f"sqlite:///{tmp_path}/other.db"  # the run dir imported into another store: the same dates
    assert import_run_dir(result.run_dir, other).outcome == "imported"
    [imported] = store.find_runs("table2", uri=other)
    info = store.client(other).get_run(imported["run_id"]).info
    assert (info.start_time, info.end_time, imported["tags"][TIMES]) == (start, end, RESULTS)
    assert no_machine_path(imported["tags"] | imported["params"], tmp_path, project_root()) == []
    assert imported["params"] == params  # as the trainer logged them
    assert imported["metrics"]["final/sgn_test"] == record["metrics"]["sgn_test"]
    history = store.client(other).get_metric_history(imported["run_id"], "train/success_sgn")
    assert all(start <= m.timestamp <= end for m in history)


def test_a_run_dir_from_before_is_dated_by_its_files_and_its_curve(tmp_path):
    curve = [(64, "charts/fps", 32.0), (64, "train/loss", 1.0), (128, "charts/fps", 16.0), (128, "perf/eval_s", 3.0)]
    run = write_run(tmp_path, "old", "old-s0", "c" * 32, curve=curve)  # no started_at, no ended_at
    os.utime(run / METRICS, (1_700_000_000, 1_700_000_000))
    points = [(s, k, v) for s, k, v in curve]
    start, end, how, when = run_times(json.loads((run / RESULTS).read_text()), run, points, {})
    lasted = 64 / 32 + 64 / 16 + 3  # each update's frames over its frames/s, and the evaluation
    assert (start, end) == (1_700_000_000_000 - lasted * 1000, 1_700_000_000_000)
    assert how.startswith("estimated: ended when modified metrics.csv")
    assert (when(64), when(128)) == (start + 2000, end)
    committed = {run / RESULTS: 1_600_000_000.0}  # the commit that added results.json: earlier, so the end
    assert run_times({}, run, points, committed)[1] == 1_600_000_000_000


def test_commit_times_reads_when_git_added_each_results_json(tmp_path):
    run = write_run(tmp_path, "git", "g-s0", "d" * 32)
    env = os.environ | {"GIT_AUTHOR_DATE": "@1650000000 +0000", "GIT_COMMITTER_DATE": "@1650000000 +0000"}
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-C", str(tmp_path)]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", "runs"], check=True)
    subprocess.run([*git, "commit", "-qm", "run"], check=True, env=env)
    assert commit_times([run]) == {(run / RESULTS).resolve(): 1_650_000_000.0}
    assert commit_times([write_run(tmp_path / "no-git", "t", "n", "e" * 32)]) == {}


def test_paths_and_names_in_the_store_hold_no_path_of_the_machine():
    root = portable.checkout_root()
    assert portable.portable(str(root / "runs")) == "runs"
    assert portable.portable(f"('{root}/a', '/tmp/b')") == "('a', '" + os.path.relpath("/tmp/b", root) + "')"
    for kept in ("sqlite:///x/mlflow.db", "env/tasks", "1/2", "train/success_sgn", "https://host/a"):
        assert portable.portable(kept) == kept
    assert display_name(root / "runs" / "table2" / "x", "x") == "x"
    assert display_name(root / "runs" / "extended" / "table2" / "x", "x") == "x [extended]"
    assert display_name(root / "scratch" / "runs" / "test" / "x", "x") == "x"  # the smoke profile's root
    assert display_name(root / "elsewhere" / "t" / "x", "x") == "x [elsewhere]"
    assert provenance.experiment_note("eqa_gate").endswith("(`emml run experiments/eqa_gate`).")
    assert "no table file" in provenance.experiment_note("my-own")


def test_a_campaign_worktree_writes_paths_relative_to_its_checkout(tmp_path, monkeypatch):
    """A campaign trains from <checkout>/.campaign/<sha> into the checkout's runs/: its paths read 'runs/...'."""
    (tmp_path / "pyproject.toml").write_text("")
    pinned = tmp_path / ".campaign" / "abc1234"
    pinned.mkdir(parents=True)
    (pinned / "pyproject.toml").write_text("")
    monkeypatch.setattr(paths, "project_root", lambda: pinned)  # checkout_root reads it from its own module
    assert portable.checkout_root() == tmp_path
    assert portable.portable(str(tmp_path / "runs" / "table2")) == "runs/table2"
    assert display_name(tmp_path / "runs" / "table2" / "x", "x") == "x"
