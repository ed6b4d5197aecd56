"""Where SGN episodes end (emml/eval/diagnose_sgn.py): every episode gets one end, the success rate is greedy
evaluation's for the same seeds, and a wrong-object end names the object the agent walked into. A scripted walker
gives ends known in advance; a smoke checkpoint (64 frames: it times out everywhere) checks the command's plumbing."""

import dataclasses
import json

import pytest
import torch
from typer.testing import CliRunner

from emml.cli import app
from emml.config.schema import DoomConfig
from emml.envs.doom import FORWARD, LEFT
from emml.envs.vector import make_env
from emml.eval.diagnose_sgn import (
    ENDS,
    NONE,
    TARGET,
    TIMEOUT,
    WRONG,
    _matched_chance,
    diagnose_sgn,
    sgn_table,
    shared_attributes,
)
from emml.eval.evaluate import evaluate
from emml.tasks.language import Vocabulary, load_dataset
from tests.conftest import SMOKE
from tests.fakes import ScriptedModel

AHEAD = 2
"""The Easy slot straight ahead of the start: walking forward reaches it (in 4 steps at the smoke size)."""


class _OneMove(ScriptedModel):
    """Always the same move: 'forward' walks into the object ahead, 'left' turns on the spot until the time-out."""

    def __init__(self, move: int, vocab_size: int):
        super().__init__()
        self.move, self.vocab_size = move, vocab_size
        self.cfg = type("Cfg", (), {"control": "none", "name": f"always-{move}"})

    def forward(self, obs, state, episode_start):
        t, b = obs["time"].shape
        logits = torch.zeros(t, b, 4)
        logits[..., self.move] = 1.0
        return type("Out", (), {"logits": logits, "answer_logits": torch.zeros(t, b, self.vocab_size)}), state


def _cfg(**over) -> DoomConfig:
    words = Vocabulary.from_dataset(load_dataset("doom")).words
    return DoomConfig(**SMOKE, tasks="sgn", vocabulary=words, **over)


def _check_adds_up(split: dict, n: int) -> None:
    s, records = split["summary"], split["records"]
    assert len(records) == s["episodes"] == n and sum(s["ends"].values()) == n
    assert all(r["end"] in ENDS and (r["end"] == TARGET) == r["success"] for r in records)
    assert s["success"] == pytest.approx(s["ends"][TARGET] / n)
    assert sum(r["episodes"] for r in split["instructions"]) == n
    assert {r["instruction"] for r in split["instructions"]} == {r["instruction"] for r in records}
    wrong = [r for r in records if r["end"] == WRONG]
    assert s["wrong_matched"][NONE] == sum(not r["matched"] for r in wrong)
    assert sum(s["wrong_slots"].values()) == len(wrong) and sum(s["reached_slots"].values()) == n - s["ends"][TIMEOUT]
    assert sum(s["target_slots"].values()) == n and s["wrong_matched_chance"][NONE] <= len(wrong)
    ended, groups = n - s["ends"][TIMEOUT], load_dataset("doom").word_groups
    for group in ("colors", "objects"):  # each object has one colour and one object word
        for key in ("reached", "uniform", "targets"):
            assert sum(s["reached_words"][w][key] for w in groups[group]) == pytest.approx(ended, abs=0.3)
    for word, v in s["by_word"].items():
        mine = [r["success"] for r in records if word in r["instruction"].split()]
        assert v == {"episodes": len(mine), "success": pytest.approx(sum(mine) / len(mine))}


def test_shared_attributes_are_the_instructions_named_ones():
    ds = load_dataset("doom")
    assert shared_attributes(ds, "go to the red tall pillar", "ShortRedTorch") == ["color"]
    assert shared_attributes(ds, "go to the short red torch", "ShortRedTorch") == ["object", "color", "size"]
    assert shared_attributes(ds, "go to the torch", "GreenArmor") == []
    assert shared_attributes(ds, "go to the largest red object", "RedSkull") == ["color"]  # the superlative is not one


def test_the_chance_share_is_a_uniform_pick_among_the_distractors():
    ds = load_dataset("doom")
    scene = ["BlueTorch", "RedTorch", "RedSkull", "GreenArmor", "YellowCard"]  # the target, red torch, at slot 1
    record = {"instruction": "go to the red torch", "scene": scene, "target_slot": 1}
    assert _matched_chance([record], ds) == {"object": 0.25, "color": 0.25, "size": 0.0, "none": 0.5}
    assert _matched_chance([record, {**record, "instruction": "go to the tall torch"}], ds) == {
        "object": 0.5,  # the blue torch, tall, shares object and size with 'tall torch'
        "color": 0.25,
        "size": 0.25,
        "none": 1.25,  # plus the skullkey, armor and keycard, which share nothing with it
    }


def test_walking_ahead_ends_at_the_object_in_the_middle_slot(no_leftovers):
    cfg = _cfg(max_steps=12)
    n = 10  # seed 308 puts the target ahead: one success
    model = _OneMove(FORWARD, len(cfg.vocabulary))
    result = diagnose_sgn(model, cfg, n, seed=300, splits=("test",), batch=2)
    assert list(result["splits"]) == ["test"]
    split = result["splits"]["test"]
    _check_adds_up(split, n)
    records = split["records"]
    assert [r["seed"] for r in records] == list(range(300, 300 + n))
    assert all(r["reached_slot"] == AHEAD and r["steps"] == 4 for r in records)
    assert all((r["end"] == TARGET) == (r["target_slot"] == AHEAD) for r in records)
    assert split["summary"]["reached_slots"] == {0: 0, 1: 0, 2: n, 3: 0, 4: 0}
    ds = load_dataset("doom")
    for w, v in split["summary"]["reached_words"].items():  # the object ahead, counted by its words
        assert v["reached"] == sum(w in ds.actors[r["scene"][AHEAD]].words() for r in records)
    # the object named is the one the seed's scene puts ahead (the scene drawn again by a plain env)
    env = make_env(dataclasses.replace(cfg, split="test"))
    try:
        for r in records:
            env.reset(seed=r["seed"])
            assert env.episode.sentence.text == r["instruction"]
            assert r["reached"] == env.episode.scene[AHEAD] and r["target"] == env.episode.scene[env.episode.target]
            if r["end"] == WRONG:
                assert r["matched"] == shared_attributes(load_dataset("doom"), r["instruction"], r["reached"])
    finally:
        env.close()
    assert any(r["end"] == WRONG for r in records)  # the seeds give the test a wrong end to check
    # greedy evaluation of the same seeds scores what the ends say (some successes: a check that can fail)
    assert 0 < split["summary"]["success"] < 1
    assert evaluate(model, cfg, n, seed=300, batch=2)["sgn_test"] == split["summary"]["success"]
    assert "go to the" in sgn_table(result) and "wrong object" in sgn_table(result)


def test_turning_on_the_spot_times_out(no_leftovers):
    cfg = _cfg(max_steps=5)
    result = diagnose_sgn(_OneMove(LEFT, len(cfg.vocabulary)), cfg, 3, seed=300, splits=("train",), batch=2)
    split = result["splits"]["train"]
    _check_adds_up(split, 3)
    assert split["summary"]["ends"] == {TARGET: 0, WRONG: 0, TIMEOUT: 3}
    assert all(r["steps"] == 5 and r["reached"] is None for r in split["records"])
    assert all(row["time_out"] == 1.0 and row["top_wrong"] is None for row in split["instructions"])


def test_a_checkpoints_outcomes_match_its_evaluation(tracking, no_leftovers):
    from emml.config.profiles import profile_config
    from emml.eval.evaluate import evaluate_checkpoint
    from emml.rl.trainer import train
    from emml.runs.rundir import CHECKPOINT, EVAL_SEED

    over = {"run_root": tracking["run_root"], "results_root": tracking["results_root"], "table": "test"}
    short = {"frames": 64, "eval_episodes": 1, "diagnose_episodes": 0, "env.max_steps": 12}
    path = train(profile_config("smoke", "easy", {**over, **short}, aux=True), quiet=True).run_dir / CHECKPOINT
    n = 6
    quiet = ["--episodes", "0", "--step0-episodes", "0", "--eqa-episodes", "0"]
    out = CliRunner().invoke(app, ["diagnose", str(path), *quiet, "--sgn-outcomes", str(n), "--json"])
    assert out.exit_code == 0, out.output
    result = json.loads(out.stdout)["sgn_outcomes"]
    assert result["seed"] == EVAL_SEED and list(result["splits"]) == ["train", "test"]
    scores = evaluate_checkpoint(path, n)
    for split, data in result["splits"].items():
        _check_adds_up(data, n)
        assert [r["seed"] for r in data["records"]] == list(range(EVAL_SEED, EVAL_SEED + n))
        assert data["summary"]["success"] == scores[f"sgn_{split}"]
        for r in data["records"]:
            if r["end"] == WRONG:
                assert r["reached"] != r["target"] and r["reached_words"] and r["reached_slot"] != r["target_slot"]
    text = CliRunner().invoke(app, ["diagnose", str(path), *quiet, "--sgn-outcomes", "2", "--split", "test"])
    assert text.exit_code == 0 and "test: success" in text.output and "train: success" not in text.output
    bad = CliRunner().invoke(
        app, ["diagnose", str(path), *quiet, "--sgn-outcomes", "2", "--split", "val"], env={"COLUMNS": "200"}
    )
    assert bad.exit_code == 2 and "'val' is not one of 'train', 'test', 'both'" in bad.output
