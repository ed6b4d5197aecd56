"""emml.runs.import_runs (`emml import-runs`): finished run dirs into a throwaway sqlite store, once."""

import json
import warnings

import pytest
from typer.testing import CliRunner

from emml.runs import provenance, store, tracking
from emml.runs.import_runs import (
    IMPORTED_FROM,
    as_trained,
    import_run_dir,
    import_runs,
    read_points,
    relative,
    run_dirs,
)

CONFIG = {
    "model": "dual_attention",
    "seed": 3,
    "precision": "fp32",
    "env": {"difficulty": "easy", "tasks": "both", "shaping": True, "vocabulary": ["go", "to"]},
    "ppo": {"lr": 0.00025},
}
CURVE = [(64, "train/loss", 1.0), (64, "train/success_sgn", 0.1), (128, "train/loss", 0.5)]
CURVE += [(128, "eval/sgn_test", 0.25), (192, "train/loss", 0.25), (192, "eval/sgn_test", 0.5)]


@pytest.fixture(scope="module")
def uri(tmp_path_factory):
    return f"sqlite:///{tmp_path_factory.mktemp('store') / 'mlflow.db'}"


@pytest.fixture(autouse=True)
def _env(uri, monkeypatch):
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    monkeypatch.setenv("MLFLOW_DISABLE_TELEMETRY", "true")


def write_run(root, table, name, run_id, curve=CURVE, score=None, config=CONFIG):
    """A finished run dir as the trainer leaves it (no checkpoint: the import does not read it), under root/runs."""
    run = root / "runs" / table / name
    run.mkdir(parents=True)
    (run / "metrics.csv").write_text("step,key,value\n" + "".join(f"{s},{k},{v!r}\n" for s, k, v in curve))
    results = {
        "run_name": name,
        "table": table,
        "model": "dual_attention",
        "aux": True,
        "seed": 3,
        "profile": "quick",
        "frames": 192,
        "git_sha": "abc1234",
        "run_id": run_id,
        "eval_episodes": 500,
        "metrics": score if score is not None else {"sgn_test": 0.5},
        "config": config,
    }
    (run / "results.json").write_text(json.dumps(results, indent=2))
    return run


def points_in_store(table):
    """Every metric point of every run of ``table``: (run id, key, step, value)."""
    out = []
    for run in store.find_runs(table):
        for key in run["metrics"]:
            out += [(run["run_id"], key, s, v) for s, v in store.metric_history(run["run_id"], key)]
    return sorted(out)


def test_a_finished_run_dir_is_imported_with_its_tags_params_curve_and_score(tmp_path):
    score = {"sgn_test": 0.75, "sgn_transfer:go to the red pillar": 0.4}  # rescored; a score the curve lacks
    run = write_run(tmp_path, "imp-a", "da-s3-quick", "0" * 32, score=score)
    result = import_run_dir(run)
    assert (result.outcome, result.run_id) == ("imported", "0" * 32)
    assert result.points == result.read == len(CURVE) + 2  # a short curve: every point stored
    [stored] = store.find_runs("imp-a")
    assert stored["run_id"] == result.mlflow_run_id and stored["status"] == "FINISHED"
    assert stored["run_name"] == "da-s3-quick"
    tags = stored["tags"]
    expected = {"table": "imp-a", "model": "dual_attention", "aux": "True", "seed": "3", "profile": "quick"}
    expected |= {"git_sha": "abc1234", "tasks": "both", "shaping": "True", "precision": "fp32"}
    expected |= {IMPORTED_FROM: relative(run), tracking.IMPORTED_RUN_ID: "0" * 32}
    assert relative(run) == "runs/imp-a/da-s3-quick"  # from its run root's name, wherever the checkout is
    expected |= {"trained_frames": "192", "score_eval_episodes": "500", provenance.GIT_COMMIT: "abc1234"}
    assert expected.items() <= tags.items()
    assert not {"frames", "eval_episodes"} & set(tags)  # the params' names: the target frames, the periodic episodes
    assert stored["params"] == {
        "model": "dual_attention",
        "seed": "3",
        "precision": "fp32",
        "env.difficulty": "easy",
        "env.tasks": "both",
        "env.shaping": "True",
        "env.vocabulary": "('go', 'to')",  # as a trained run's tuple, not JSON's list
        "ppo.lr": "0.00025",
    }
    rid = stored["run_id"]
    for key in ("train/loss", "train/success_sgn"):
        assert store.metric_history(rid, key) == [(s, v) for s, k, v in CURVE if k == key]
    assert store.metric_history(rid, "eval/sgn_test") == [(128, 0.25), (192, 0.5)]  # the periodic curve
    assert store.metric_history(rid, "final/sgn_test") == [(192, 0.75)]  # the score, apart
    assert store.metric_history(rid, "final/sgn_transfer:go to the red pillar") == [(192, 0.4)]


def test_a_second_import_changes_nothing(tmp_path):
    for seed in (0, 1):
        write_run(tmp_path, "imp-b", f"run-s{seed}", f"{seed + 1}" * 32)
    first = import_runs([tmp_path])
    before = points_in_store("imp-b")
    assert [r.outcome for r in first] == ["imported", "imported"] and len(before) == 2 * (len(CURVE) + 1)
    second = import_runs([tmp_path])
    assert [r.outcome for r in second] == ["skipped", "skipped"]
    assert [r.mlflow_run_id for r in second] == [r.mlflow_run_id for r in first]
    assert points_in_store("imp-b") == before and len(store.find_runs("imp-b")) == 2


def test_a_run_trained_in_this_store_is_not_duplicated(tmp_path):
    tracker = tracking.Tracker()
    trained = tracker.start("imp-c", "trained-here", {"seed": 3})
    tracker.log_metrics({"train/loss": 1.0}, step=64)
    tracker.finish()
    run = write_run(tmp_path, "imp-c", "trained-here", trained)
    result = import_run_dir(run)
    assert (result.outcome, result.mlflow_run_id) == ("skipped", trained)
    [stored] = store.find_runs("imp-c")
    assert store.metric_history(stored["run_id"], "train/loss") == [(64, 1.0)]


def test_a_trainer_resuming_an_imported_run_dir_continues_its_imported_run(tmp_path):
    run = write_run(tmp_path, "imp-d", "extended", "4" * 32)
    imported = import_run_dir(run).mlflow_run_id
    tracker = tracking.Tracker()
    tracker.mirror_to(run / "metrics.csv")
    tracker.resume_after(192)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the trainer's config (tuples) reads as the imported params: none changed
        assert tracker.start("imp-d", "extended", {"seed": 3}, as_trained(CONFIG), run_id="4" * 32) == imported
    tracker.log_metrics({"train/loss": 0.125}, step=256)
    tracker.finish()
    [stored] = store.find_runs("imp-d")
    assert store.metric_history(imported, "train/loss")[-2:] == [(192, 0.25), (256, 0.125)]
    assert stored["run_id"] == imported


def test_bad_files_fail_by_name_and_the_other_run_dirs_import(tmp_path):
    write_run(tmp_path, "imp-e", "good", "5" * 32)
    bad_json = write_run(tmp_path, "imp-e", "bad-json", "6" * 32)
    (bad_json / "results.json").write_text('{"run_id": ')
    bad_line = write_run(tmp_path, "imp-e", "bad-line", "7" * 32)
    with open(bad_line / "metrics.csv", "a") as f:
        f.write("256,train/loss\n320,train/loss,0.1\n")
    refused = write_run(tmp_path, "imp-e", "refused", "8" * 32, curve=[(64, "train/../loss", 1.0)])
    unfinished = tmp_path / "runs" / "imp-e" / "unfinished"
    unfinished.mkdir()
    (unfinished / "metrics.csv").write_text("step,key,value\n64,train/loss,1.0\n")
    results = {r.run_dir.rsplit("/", 1)[-1]: r for r in import_runs([tmp_path])}
    assert {k: r.outcome for k, r in results.items()} == {
        "bad-json": "failed",
        "bad-line": "failed",
        "good": "imported",
        "refused": "failed",
        "unfinished": "skipped",
    }
    assert results["bad-json"].reason.startswith(f"{bad_json / 'results.json'}: not JSON")
    where = f"{bad_line / 'metrics.csv'}: line {len(CURVE) + 2}"  # the line after the header and the curve
    assert results["bad-line"].reason.startswith(f"{where}: not a metric point (step,key,value): '256,train/loss'")
    assert str(refused) in results["refused"].reason and "train/../loss" in results["refused"].reason
    assert results["unfinished"].reason.startswith("unfinished")
    assert [r["run_name"] for r in store.find_runs("imp-e")] == ["good"]  # the refused one's half-made run: gone


def test_read_points_and_run_dirs(tmp_path):
    run = write_run(tmp_path, "t", "r", "9" * 32)
    assert read_points(run / "metrics.csv") == CURVE
    (run / "metrics.csv").write_text("key,step,value\n")
    with pytest.raises(ValueError, match="metrics.csv: line 1: expected the header"):
        read_points(run / "metrics.csv")
    assert run_dirs([tmp_path]) == run_dirs([run]) == [run]


def test_import_runs_command(tmp_path):
    from emml.cli import app

    run = write_run(tmp_path, "imp-f", "cli", "a" * 32)
    first = CliRunner().invoke(app, ["import-runs", str(run), "--json"])
    assert first.exit_code == 0, first.output
    assert {k: json.loads(first.stdout)[k] for k in ("imported", "skipped", "failed")} == {
        "imported": 1,
        "skipped": 0,
        "failed": 0,
    }
    again = CliRunner().invoke(app, ["import-runs", str(tmp_path)])
    assert again.exit_code == 0 and "0 imported, 1 skipped, 0 failed" in again.output
    (run / "results.json").write_text("[]")
    bad = CliRunner().invoke(app, ["import-runs", str(run)])
    assert bad.exit_code == 2 and f"{run / 'results.json'}: not a JSON object" in bad.output
