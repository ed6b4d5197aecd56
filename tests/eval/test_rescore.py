"""Re-scoring a finished run (issue 33): the checkpoint played again over the final evaluation's episodes, its
results.json and results row rewritten with the training provenance kept; unfinished runs and runs without
provenance are refused before anything is played or written."""

import json

import pytest
from typer.testing import CliRunner

from emml.cli import app
from emml.config.profiles import profile_config
from emml.eval.evaluate import evaluate_checkpoint
from emml.eval.rescore import NoProvenance, NotFinished, rescore
from emml.rl.trainer import train
from emml.runs.checkpoint import load_checkpoint, save_checkpoint
from emml.runs.naming import run_name
from emml.runs.results import read_results
from emml.runs.rundir import CHECKPOINT, RESULTS, results_csv


def _finished_run(tracking, seed: int = 0):
    over = {"run_root": tracking["run_root"], "results_root": tracking["results_root"], "table": "test"}
    over |= {"frames": 64, "eval_episodes": 1, "final_eval_episodes": 1, "diagnose_episodes": 0}
    cfg = profile_config("smoke", "easy", over, seed=seed)
    return cfg, train(cfg, quiet=True)


def test_a_finished_run_is_rescored_with_its_provenance_kept(tracking, monkeypatch, no_leftovers):
    cfg, result = _finished_run(tracking)
    before = json.loads((result.run_dir / RESULTS).read_text())
    assert (before["eval_episodes"], before["eval_seed"]) == (1, 10_000)  # the training's final evaluation

    r = rescore(result.run_dir, episodes=3, seed=10_050)
    after = json.loads((result.run_dir / RESULTS).read_text())
    expected = evaluate_checkpoint(result.run_dir / CHECKPOINT, 3, seed=10_050)
    assert r.played and after["metrics"] == expected
    assert r.after == {**expected, "eval_episodes": 3, "eval_seed": 10_050}
    assert r.before == {**before["metrics"], "eval_episodes": 1, "eval_seed": 10_000}
    for key in ("run_name", "frames", "seed", "git_sha", "run_id"):
        assert after[key] == before[key], key
    assert (after["eval_episodes"], after["eval_seed"]) == (3, 10_050) and after["scored_sha"]
    rows = read_results(results_csv(cfg))
    assert rows["run_name"].tolist() == [run_name(cfg)]  # upserted, not appended
    row = rows.iloc[0]
    assert (row["eval_episodes"], row["eval_seed"], row["scored_sha"]) == (3, 10_050, after["scored_sha"])
    assert (row["git_sha"], row["run_id"], row["frames"]) == (before["git_sha"], before["run_id"], 64)
    assert row["sgn_train"] == expected["sgn_train"] and row["eqa_test"] == expected["eqa_test"]

    again = rescore(result.run_dir / CHECKPOINT, episodes=3, seed=10_050)  # idempotent: recorded, not played
    assert not again.played and json.loads((result.run_dir / RESULTS).read_text()) == after

    def meanwhile(*args, **kwargs):  # another process adds a key to results.json while the run is played
        path = result.run_dir / RESULTS
        path.write_text(json.dumps({**json.loads(path.read_text()), "note": "kept"}))
        return evaluate_checkpoint(*args, **kwargs)

    monkeypatch.setattr("emml.eval.evaluate.evaluate_checkpoint", meanwhile)
    assert rescore(result.run_dir, episodes=3, seed=10_050, force=True).played
    assert json.loads((result.run_dir / RESULTS).read_text())["note"] == "kept"


def test_a_run_without_results_json_takes_its_provenance_from_its_row(tracking, no_leftovers):
    cfg, result = _finished_run(tracking, seed=1)
    before = json.loads((result.run_dir / RESULTS).read_text())
    (result.run_dir / RESULTS).unlink()  # a run dir whose results.json was not kept (DA seed 2 of table2 quick)
    rescore(result.run_dir, episodes=2, record=False)
    after = json.loads((result.run_dir / RESULTS).read_text())
    assert (after["git_sha"], after["run_id"], after["frames"], after["eval_episodes"]) == (
        before["git_sha"],
        before["run_id"],
        64,
        2,
    )
    assert after["config"]["seed"] == 1  # the checkpoint's config, as the trainer writes it
    row = read_results(results_csv(cfg)).iloc[0]
    assert row["eval_episodes"] == 1 and "scored_sha" not in row  # --no-record: the row is left as it was

    (result.run_dir / RESULTS).unlink()
    results_csv(cfg).unlink()
    with pytest.raises(NoProvenance, match="provenance"):
        rescore(result.run_dir, episodes=2)
    assert not (result.run_dir / RESULTS).exists()


def test_an_unfinished_run_is_refused_before_anything_is_played(tracking, monkeypatch, no_leftovers):
    cfg, result = _finished_run(tracking, seed=2)
    path = result.run_dir / CHECKPOINT
    save_checkpoint(path, {**load_checkpoint(path), "finished": False})
    results, table = (result.run_dir / RESULTS).read_text(), results_csv(cfg).read_text()
    monkeypatch.setattr("emml.eval.evaluate.evaluate_checkpoint", lambda *a, **k: pytest.fail("played"))
    with pytest.raises(NotFinished, match="unfinished run"):
        rescore(result.run_dir, episodes=2)
    out = CliRunner().invoke(app, ["rescore", str(result.run_dir), "--episodes", "2"])
    assert out.exit_code == 2 and "unfinished run (frame 64 of 64)" in out.output
    assert (result.run_dir / RESULTS).read_text() == results and results_csv(cfg).read_text() == table
