"""The envelope of every greedy play (emml.eval.evaluate.playing); EQA counted per question (issue 81): each episode
under the question its reset drew, the counts summing to the accuracy."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from torch import nn

from emml.config.schema import DoomConfig
from emml.envs.vector import make_env
from emml.eval.evaluate import evaluate, play, playing, question_counts
from emml.tasks.language import Vocabulary, load_dataset
from tests.conftest import SMOKE
from tests.fakes import ScriptedModel


class _Env:
    def __init__(self, cfg, closed: list):
        self.cfg, self._closed = cfg, closed

    def close(self):
        self._closed.append(self)


@pytest.mark.parametrize("fail_in", ["body", "third_env"])
def test_an_error_closes_every_env_made_and_restores_the_training_mode(fail_in):
    closed, made = [], []
    model = nn.Linear(2, 2).train()

    def make(cfg):
        if fail_in == "third_env" and len(made) == 2:
            raise RuntimeError("engine did not start")
        made.append(_Env(cfg, closed))
        return made[-1]

    with pytest.raises(RuntimeError):
        with playing(model, "cfg", 3, make=make) as envs:
            assert not model.training and len(envs) == 3
            raise RuntimeError("episode failed")
    assert closed == made and len(made) in (2, 3) and model.training


def test_an_eval_mode_model_stays_in_eval_mode():
    model = nn.Linear(2, 2).eval()
    with playing(model, "cfg", 1, make=lambda cfg: _Env(cfg, [])) as (env,):
        assert env.cfg == "cfg"
    assert not model.training


# --- EQA per question (issue 81) -----------------------------------------------------------------------------------
class _FakeEnv:
    """No engine: episode ``seed`` asks question ``q{seed % 3}``, lasts ``1 + seed % 4`` moves and succeeds when
    its seed is even; lengths differ, so the lockstep hands the envs the plan's episodes out of step."""

    def reset(self, seed, options=None):
        self.seed, self.t = seed, 0
        return {"time": np.zeros((), dtype=np.int64)}, {"text": f"q{seed % 3}", "success": False}

    def step(self, action):
        self.t += 1
        done = self.t >= 1 + self.seed % 4
        return {"time": np.zeros((), dtype=np.int64)}, 0.0, done, False, {"success": done and self.seed % 2 == 0}

    def close(self):
        pass


class _Answers(ScriptedModel):
    """Answers word ``word`` at once, every episode (a blind 'best answer' policy when ``word`` is the prior's)."""

    def __init__(self, words: list[str], word: str):
        super().__init__()
        self.n, self.word = len(words), words.index(word)

    def forward(self, obs, state, episode_start):
        t, b = obs["time"].shape
        logits, answer = torch.zeros(t, b, 4), torch.zeros(t, b, self.n)
        logits[..., 3] = 1.0  # 'answer' (emml/envs/doom.py's last move)
        answer[..., self.word] = 1.0
        return SimpleNamespace(logits=logits, answer_logits=answer), state


def test_play_names_each_planned_episode_s_sentence_in_plan_order():
    plan = [(s, None) for s in (7, 4, 9, 2, 5, 6, 3)]
    sentences = []
    outcomes = play(_Answers(["a"], "a"), [_FakeEnv(), _FakeEnv(), _FakeEnv()], plan, "cpu", sentences=sentences)
    assert sentences == [f"q{s % 3}" for s, _ in plan]
    assert outcomes == [s % 2 == 0 for s, _ in plan]


def test_question_counts_group_the_episodes_by_question_sorted():
    counts = question_counts(["b", "a", "b", "b", "a"], [True, False, False, True, False])
    assert counts == {"a": {"successes": 0, "episodes": 2}, "b": {"successes": 2, "episodes": 3}}
    assert list(counts) == ["a", "b"]
    with pytest.raises(ValueError, match="2 sentences for 1 outcomes"):
        question_counts(["a", "b"], [True])


QUESTIONS = ("what color is the pillar", "which object is red in color", "what color is the torch")
"""Two training questions and one test question (emml/tasks/doom.toml)."""


def test_evaluate_counts_each_question_s_episodes_as_the_env_draws_them(no_leftovers):
    words = Vocabulary.from_dataset(load_dataset("doom")).words
    cfg = DoomConfig(**SMOKE, tasks="both", instructions=QUESTIONS, vocabulary=words, max_steps=4)
    model = _Answers(list(words), "pillar")
    episodes, seed = 9, 900
    scores = evaluate(model, cfg, episodes, seed=seed)
    assert set(scores) == {"eqa_train", "eqa_test"} and set(scores.questions) == {"eqa_train", "eqa_test"}
    for split in ("train", "test"):
        # the oracle: each seed's question and answer, read from one env's reset; 'pillar' succeeds iff the answer
        expected: dict = {}
        env = make_env(
            dataclasses.replace(
                cfg, tasks="eqa", split=split, instructions=tuple(q for q in QUESTIONS if split_of(q) == split)
            )
        )
        try:
            for i in range(episodes):
                info = env.reset(seed=seed + i)[1]
                c = expected.setdefault(info["text"], {"successes": 0, "episodes": 0})
                c["episodes"] += 1
                c["successes"] += env.unwrapped.episode.answer == "pillar"
        finally:
            env.close()
        assert scores.questions[f"eqa_{split}"] == dict(sorted(expected.items()))
        total = scores.questions[f"eqa_{split}"].values()
        assert sum(c["successes"] for c in total) / sum(c["episodes"] for c in total) == scores[f"eqa_{split}"]
    train = scores.questions["eqa_train"]
    assert len(train) == 2 and train["what color is the pillar"]["successes"] == 0  # its answers are colours
    red = train["which object is red in color"]
    assert 0 < red["successes"] < red["episodes"]  # seeds 900-908: 2 of its 8 episodes ask about a red pillar
    only = evaluate(model, cfg, episodes, seed=seed, tasks=("eqa",))
    assert only == scores and only.questions == scores.questions
    with pytest.raises(ValueError, match="allowed are \\['eqa', 'sgn'\\]"):
        evaluate(model, cfg, episodes, tasks=("nav",))


def split_of(question: str) -> str:
    return load_dataset("doom").find(question).split


@pytest.mark.parametrize("compiled", [False, True])
def test_evaluate_checkpoint_compiles_the_model_only_when_asked(compiled, monkeypatch):
    """``compiled``: the model through emml.models.compiled.compile_model (the trainer's), else as loaded."""
    import emml.eval.evaluate as module

    model, cfg = object(), SimpleNamespace(env="env")
    monkeypatch.setattr(module, "load_model", lambda path, device, control: (model, cfg))
    seen = {}
    monkeypatch.setattr("emml.models.compiled.compile_model", lambda m: seen.setdefault("compiled", m))
    monkeypatch.setattr(module, "evaluate", lambda m, env, episodes, **k: seen.setdefault("played", (m, env, episodes)))
    module.evaluate_checkpoint("ckpt", 7, compiled=compiled)
    assert seen.get("compiled") is (model if compiled else None) and seen["played"] == (model, "env", 7)


def test_evaluate_writes_each_score_to_its_declared_metric(monkeypatch):
    """The columns are the declaration's (emml/eval/metrics.py), not spelled by the evaluation: a metric renamed
    there is the column the scores and the per-question counts are written to."""
    import emml.eval.evaluate as evaluation
    from emml.eval import metrics

    renamed = [dataclasses.replace(m, name="eqa_heldout") if m.name == "eqa_test" else m for m in metrics.DECLARED]
    monkeypatch.setattr(metrics, "DECLARED", tuple(renamed))
    engine_free = contextmanager_playing(evaluation.playing)
    monkeypatch.setattr(evaluation, "playing", engine_free)
    words = Vocabulary.from_dataset(load_dataset("doom")).words
    scores = evaluate(_Answers(list(words), "red"), DoomConfig(**SMOKE, vocabulary=words), 3)
    assert list(scores) == ["sgn_train", "sgn_test", "eqa_train", "eqa_heldout"]  # task by task, split by split
    assert list(scores.questions) == ["eqa_train", "eqa_heldout"]


def contextmanager_playing(playing):
    """`playing` on engine-free envs (`_FakeEnv`)."""

    def engine_free(model, cfg, n=1, make=None):
        return playing(model, cfg, n, make=lambda c: _FakeEnv())

    return engine_free
