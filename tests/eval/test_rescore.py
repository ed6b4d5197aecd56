"""Re-scoring a finished run (issue 33): the checkpoint played again over the final evaluation's episodes, its
results.json and results row rewritten with the training provenance kept; unfinished runs and runs without
provenance are refused before anything is played or written. EQA per question (issue 81): the trainer keeps the
counts, a replay of an older run finds the same ones, and one that does not reproduce the row writes nothing."""

import json

import pytest
from typer.testing import CliRunner

from emml.cli import app
from emml.config.profiles import profile_config
from emml.eval.evaluate import evaluate_checkpoint
from emml.eval.rescore import NoProvenance, NotFinished, NotReproduced, check_reproduced, rescore, rescore_questions
from emml.rl.trainer import train
from emml.runs.checkpoint import load_checkpoint, save_checkpoint
from emml.runs.naming import run_name
from emml.runs.results import questions_path, read_questions, read_results
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


# --- EQA per question (issue 81) -----------------------------------------------------------------------------------
def _counted_run(tracking, seed: int):
    """A finished smoke run whose final evaluation played 4 episodes per setting, then stripped of its per-question
    counts (results.json's "questions", the per-question file), as a run finished before they were kept."""
    over = {"run_root": tracking["run_root"], "results_root": tracking["results_root"], "table": "test"}
    over |= {"frames": 64, "eval_episodes": 1, "final_eval_episodes": 4, "diagnose_episodes": 0}
    cfg = profile_config("smoke", "easy", over, seed=seed)
    result = train(cfg, quiet=True)
    path = result.run_dir / RESULTS
    trained = json.loads(path.read_text())
    path.write_text(json.dumps({k: v for k, v in trained.items() if k != "questions"}))
    questions_path(results_csv(cfg)).unlink()
    return cfg, result, trained


def _totals(questions: dict) -> dict:
    return {
        s: (sum(c["successes"] for c in q.values()), sum(c["episodes"] for c in q.values()))
        for s, q in questions.items()
    }


def test_the_trainer_keeps_eqa_per_question_and_a_replay_finds_the_same_counts(tracking, monkeypatch, no_leftovers):
    cfg, result, trained = _counted_run(tracking, seed=3)
    # the trainer's final evaluation: counts per question in results.json, summing to its scores
    assert set(trained["questions"]) == {"eqa_train", "eqa_test"}
    for setting, (k, n) in _totals(trained["questions"]).items():
        assert n == 4 and k / n == trained["metrics"][setting]
    row_before = results_csv(cfg).read_bytes()

    r = rescore_questions(result.run_dir)
    assert r.played and r.questions == trained["questions"]  # the same episodes, the same counts
    assert json.loads((result.run_dir / RESULTS).read_text()) == trained  # results.json as the trainer wrote it
    assert results_csv(cfg).read_bytes() == row_before  # the results row is not touched
    rows = read_questions(questions_path(results_csv(cfg)))
    assert set(rows["run_name"]) == {run_name(cfg)} and set(rows["run_id"]) == {trained["run_id"]}
    assert rows.groupby("split")["episodes"].sum().to_dict() == {"test": 4, "train": 4}

    monkeypatch.setattr("emml.eval.evaluate.evaluate_checkpoint", lambda *a, **k: pytest.fail("played"))
    again = rescore_questions(result.run_dir)  # counted already for this training: not played
    assert not again.played and again.questions == trained["questions"]


def test_a_replay_that_does_not_reproduce_the_row_writes_nothing(tracking, no_leftovers):
    cfg, result, trained = _counted_run(tracking, seed=4)
    table = results_csv(cfg)
    rows = read_results(table)
    k, n = _totals(trained["questions"])["eqa_test"]
    rows.loc[0, "eqa_test"] = (k + 1) / n if k < n else (k - 1) / n  # one episode off: another evaluation's row
    rows.to_csv(table, index=False)
    before = (result.run_dir / RESULTS).read_text()
    with pytest.raises(NotReproduced, match=f"{run_name(cfg)}: eqa_test per question sums to {k}/4"):
        rescore_questions(result.run_dir)
    assert (result.run_dir / RESULTS).read_text() == before and not questions_path(table).exists()
    out = CliRunner().invoke(app, ["rescore", "--questions", str(result.run_dir)])
    assert out.exit_code == 1 and "eqa_test per question sums to" in out.output and "not written" in out.output
    assert not questions_path(table).exists()


def test_check_reproduced_compares_every_setting_with_its_row():
    counts = {"eqa_test": {"a": {"successes": 1, "episodes": 2}, "b": {"successes": 2, "episodes": 2}}}
    check_reproduced("r", counts, {"eqa_test": 0.75}, 4)
    with pytest.raises(NotReproduced, match="r: eqa_test per question sums to 3/4 = 0.7500, its row reads 0.5000"):
        check_reproduced("r", counts, {"eqa_test": 0.5}, 4)
    with pytest.raises(NotReproduced, match="3/4"):  # the right rate over other episodes is not this evaluation
        check_reproduced("r", counts, {"eqa_test": 0.75}, 8)
    with pytest.raises(NotReproduced, match="the row has no eqa_test"):
        check_reproduced("r", counts, {"eqa_train": 0.75}, 4)


def test_a_full_rescore_replaces_the_counts_with_those_of_its_episodes(tracking, no_leftovers):
    cfg, result, trained = _counted_run(tracking, seed=5)
    rescore(result.run_dir, episodes=6, seed=10_050)
    after = json.loads((result.run_dir / RESULTS).read_text())
    for setting, (k, n) in _totals(after["questions"]).items():
        assert n == 6 and k / n == after["metrics"][setting]
    rows = read_questions(questions_path(results_csv(cfg)))
    assert rows.groupby("split")["episodes"].sum().to_dict() == {"test": 6, "train": 6}
    assert "questions" not in read_results(results_csv(cfg)).columns  # results.json's only (rundir.JSON_ONLY)


# --- a run its trainer scored compiled (TrainConfig.compile) ---------------------------------------------------------
def _compile_as(result, value: str) -> None:
    """The run's checkpoint as if trained under ``compile=value`` (its config's field; nothing else changes)."""
    path = result.run_dir / CHECKPOINT
    ckpt = load_checkpoint(path)
    ckpt["config"] = {**ckpt["config"], "compile": value}
    save_checkpoint(path, ckpt)


def _eager_one_off(monkeypatch, compiled_too: bool = False) -> list[bool]:
    """evaluate_checkpoint with its eager replay one EQA test episode off the trainer's counts (as float sums that
    differ in the last bits flipped one greedy answer), its compiled one as played (or off too: ``compiled_too``);
    returns the ``compiled`` flag of each call."""
    calls: list[bool] = []

    def played(*args, compiled: bool = False, **kwargs):
        calls.append(compiled)
        scores = evaluate_checkpoint(*args, **kwargs)
        if compiled_too or not compiled:
            question, counts = next(iter(scores.questions["eqa_test"].items()))
            k = counts["successes"]
            scores.questions["eqa_test"][question] = {**counts, "successes": k + 1 if k == 0 else k - 1}
        return scores

    monkeypatch.setattr("emml.eval.evaluate.evaluate_checkpoint", played)
    return calls


def test_a_run_scored_compiled_is_replayed_compiled_where_eager_does_not_reproduce(tracking, monkeypatch, no_leftovers):
    cfg, result, trained = _counted_run(tracking, seed=6)
    _compile_as(result, "on")
    calls = _eager_one_off(monkeypatch)
    r = rescore_questions(result.run_dir)
    assert calls == [False, True] and r.played and r.compiled
    assert r.questions == trained["questions"]  # the compiled replay's counts, those of the row's episodes
    assert json.loads((result.run_dir / RESULTS).read_text())["questions"] == trained["questions"]
    rows = read_questions(questions_path(results_csv(cfg)))
    assert rows.groupby("split")["successes"].sum().to_dict() == {
        split: _totals(trained["questions"])[f"eqa_{split}"][0] for split in ("test", "train")
    }


def test_a_run_trained_uncompiled_is_not_replayed_compiled(tracking, monkeypatch, no_leftovers):
    cfg, result, trained = _counted_run(tracking, seed=6)
    _compile_as(result, "off")
    calls = _eager_one_off(monkeypatch)
    with pytest.raises(NotReproduced, match="eqa_test per question sums to") as raised:
        rescore_questions(result.run_dir)
    assert calls == [False] and "compiled" not in str(raised.value)
    assert "questions" not in json.loads((result.run_dir / RESULTS).read_text())
    assert not questions_path(results_csv(cfg)).exists()


def test_a_run_neither_replay_reproduces_writes_nothing_and_says_both(tracking, monkeypatch, no_leftovers):
    cfg, result, trained = _counted_run(tracking, seed=6)
    _compile_as(result, "on")
    calls = _eager_one_off(monkeypatch, compiled_too=True)
    with pytest.raises(NotReproduced, match=r"\(played eagerly\); compiled, as its trainer plays: .*eqa_test per q"):
        rescore_questions(result.run_dir)
    assert calls == [False, True]
    assert "questions" not in json.loads((result.run_dir / RESULTS).read_text())
    assert not questions_path(results_csv(cfg)).exists()
