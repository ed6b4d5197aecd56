"""The per-question EQA diagnostics (emml/eval/diagnose_eqa.py) are computed from the episodes they play: the same
outcomes as greedy evaluation, answers and attention per episode, and the gate the model reads in Eq. 4."""

import dataclasses

import numpy as np
import torch

from emml.config.schema import DoomConfig
from emml.envs.vector import make_env
from emml.eval.diagnose_eqa import NO_ANSWER, diagnose_eqa, eqa_table, split_means
from emml.eval.evaluate import play
from emml.models import build_model
from emml.models.type_gate import TypeGate
from emml.tasks.language import Vocabulary, load_dataset
from tests.conftest import SMOKE
from tests.fakes import ScriptedModel

QUESTIONS = ("what color is the pillar", "what color is the torch")
"""One training question and one test question: two splits, one row each."""
EPISODES = 3


def _env_cfg(**over):
    ds = load_dataset("doom")
    words = Vocabulary.from_dataset(ds).words
    return DoomConfig(**SMOKE, tasks="eqa", instructions=QUESTIONS, vocabulary=words, max_steps=6, **over)


def _model(cfg, name="dual_attention", **options):
    torch.manual_seed(0)
    return build_model(name, len(cfg.vocabulary), cfg.height, cfg.width, cfg.max_steps, **options)


def test_each_question_row_is_computed_from_its_episodes(no_leftovers):
    cfg = _env_cfg()
    model = _model(cfg)
    result = diagnose_eqa(model, cfg, episodes=EPISODES, seed=500)
    rows = {r["question"]: r for r in result["questions"]}
    assert [(r["split"], r["question"]) for r in result["questions"]] == [
        ("train", QUESTIONS[0]),
        ("test", QUESTIONS[1]),
    ]
    for k, (question, r) in enumerate(rows.items()):
        assert r["episodes"] == EPISODES and sum(r["answers"].values()) == EPISODES
        assert set(r["answers"]) <= set(cfg.vocabulary) | {NO_ANSWER}
        assert sum(a["episodes"] for a in r["by_answer"].values()) == EPISODES
        # the same outcomes as greedy evaluation playing the same seeds (the split's one question: seeds 500 + i)
        split = "train" if k == 0 else "test"
        env_cfg = dataclasses.replace(cfg, split=split, instructions=(question,))
        envs = [make_env(env_cfg) for _ in range(2)]
        try:
            plan = [(500 + i, {"sentence": question}) for i in range(EPISODES)]
            outcomes = play(model, envs, plan, "cpu")
        finally:
            for env in envs:
                env.close()
        assert r["accuracy"] == np.mean(outcomes)
        assert 1 <= r["steps"] <= cfg.max_steps
        # attention: per episode, one scene object (or none in view); the Eq. 1 terms are the question's words
        assert sum(r["attended"].values()) == EPISODES and 0 <= r["attention_on_referent"] <= 1
        assert list(r["ga1_at_referent"]) == question.split()
        assert list(r["detectors_at_referent"]) == list(load_dataset("doom").word_groups["colors"])  # colour answers
        assert -1 <= r["answer_lead"] <= 1
        # the gate is the model's x_sent for the question, every channel
        tokens = torch.tensor([Vocabulary(tuple(cfg.vocabulary)).encode(question, cfg.max_words)])
        x_sent = model.text_encoder(tokens)[1][0].detach().numpy()
        np.testing.assert_allclose(list(r["gate"].values()), x_sent, atol=5e-4)
        assert r["gate_summary"]["question_words"].keys() == {"pillar" if k == 0 else "torch"}
    text = eqa_table(result)
    assert all(q in text for q in QUESTIONS) and "GA2 gate (Eq. 4)" in text and "at the referent" in text
    assert "Detectors at the referent" in text and "lead" in text
    # one question per split here: each split's mean row is that question's
    for r in result["questions"]:
        m = result["splits"][r["split"]]
        assert m["questions"] == 1 and m["accuracy"] == r["accuracy"] and m["steps"] == r["steps"]
        assert m["attention_on_referent"] == r["attention_on_referent"]
    assert "train  mean over its 1 questions" in text and "test   mean over its 1 questions" in text


def test_a_split_mean_counts_each_question_once():
    rows = [
        {"split": "train", "accuracy": 1.0, "steps": 1.0, "attention_on_referent": 0.5},
        {"split": "train", "accuracy": 0.0, "steps": 3.0, "attention_on_referent": 0.0},
        {"split": "test", "accuracy": 0.25, "steps": 2.0, "attention_on_referent": None},
    ]
    means = split_means(rows)
    assert list(means) == ["train", "test"]  # the order the rows give
    assert means["train"] == {"questions": 2, "accuracy": 0.5, "steps": 2.0, "attention_on_referent": 0.25}
    assert means["test"] == {"questions": 1, "accuracy": 0.25, "steps": 2.0, "attention_on_referent": None}


class _Oracle(ScriptedModel):
    """Answers at once, with the colour whose aux label covers most of the referent's cells (privileged), attends
    to exactly the referent's cells, and its detectors are the aux labels (sigmoid(±10)): every row of the
    diagnostics is known in advance."""

    def __init__(self, words):
        super().__init__()
        self.words = words
        self.colours = [words.index(w) for w in load_dataset("doom").word_groups["colors"]]
        self.cfg = type("Cfg", (), {"control": "none", "name": "oracle"})
        self.fusion = None

    def forward(self, obs, state, episode_start):
        t, b = obs["time"].shape
        target = obs["target"].float()  # (t, b, h, w)
        cover = (obs["aux"][:, :, self.colours].float() * target[:, :, None]).sum((-2, -1))  # (t, b, colours)
        answer = torch.zeros(t, b, len(self.words))
        answer.scatter_(-1, torch.tensor(self.colours)[cover.argmax(-1)].unsqueeze(-1), 1.0)
        logits = torch.zeros(t, b, 4)
        logits[..., 3] = 1.0  # 'answer'
        attention = target / target.sum((-2, -1), keepdim=True).clamp(min=1)
        aux = (obs["aux"].float() * 2 - 1) * 10  # logits whose sigmoid is the label
        return type(
            "Out", (), {"logits": logits, "answer_logits": answer, "attention": attention, "aux_logits": aux}
        ), state


def test_an_oracle_gets_every_row_right(no_leftovers):
    cfg = _env_cfg()
    result = diagnose_eqa(_Oracle(list(cfg.vocabulary)), cfg, episodes=EPISODES, seed=700)
    assert "no GA2 gate" in result["gate_note"]
    for r in result["questions"]:
        assert r["accuracy"] == 1.0 and r["steps"] == 1.0
        assert r["answers"] == {w: a["episodes"] for w, a in r["by_answer"].items()}  # the correct words, counted
        assert r["attention_on_referent"] == 1.0 and r["attention_mass_on_referent"] == 1.0
        kind = r["question"].split()[-1]  # 'pillar' or 'torch': the referent's object word
        assert all(words.endswith(kind) for words in r["attended"])
        # Eq. 5's inputs at the referent: every colour, the referent's own label the highest
        assert list(r["detectors_at_referent"]) == list(load_dataset("doom").word_groups["colors"])
        assert r["answer_lead"] > 0  # its own colour covers every cell, a neighbour's at most some
    assert all(m["accuracy"] == 1.0 and m["attention_on_referent"] == 1.0 for m in result["splits"].values())


def test_under_the_type_gate_the_row_shows_the_gate_that_replaced_x_sent(no_leftovers):
    cfg = _env_cfg()
    model = _model(cfg, control="type_gate")
    model.type_gate = TypeGate(tuple(cfg.vocabulary), load_dataset("doom"))
    result = diagnose_eqa(model, cfg, episodes=1, seed=500)
    colours = set(load_dataset("doom").word_groups["colors"])
    for r in result["questions"]:
        assert {w for w, g in r["gate"].items() if g > 0} == colours  # a colour question: only colours open
    assert result["control"] == "type_gate"


def test_a_model_without_gate_or_attention_is_reported_not_an_error(no_leftovers):
    cfg = _env_cfg()
    result = diagnose_eqa(_model(cfg, "image_only"), cfg, episodes=1, seed=500)
    assert "no GA2 gate" in result["gate_note"] and "no spatial attention" in result["attention_note"]
    assert all(r["gate"] is None and r["attended"] is None for r in result["questions"])
    assert "no GA2 gate" in eqa_table(result)
    assert all(m["attention_on_referent"] is None for m in result["splits"].values())  # n/a, not 0
    sgn_only = dataclasses.replace(cfg, tasks="sgn", instructions=None)
    assert diagnose_eqa(_model(cfg), sgn_only, episodes=1)["questions"] == []


def test_an_answer_word_whose_relu_logit_is_0_on_every_frame_is_named_closed(no_leftovers):
    """The baselines' head softmax(ReLU(Linear(x_S))): a word whose Linear output is below 0 on every frame has logit
    exactly 0 and no gradient; the diagnostics name it (and only it), and under softplus nothing is closed."""
    cfg = _env_cfg()
    answers = list(load_dataset("doom").answer_words())
    found = {}
    for activation in ("relu", "softplus"):
        model = _model(cfg, "image_only", answer_activation=activation)
        bias = model.fusion.answer.linear.bias
        with torch.no_grad():
            for w in answers:
                bias[cfg.vocabulary.index(w)] = -100.0 if w == "blue" else 100.0
        found[activation] = diagnose_eqa(model, cfg, episodes=1, seed=500)
    closed = found["relu"]
    assert closed["closed_answers"] == ["blue"] and closed["answer_peak"]["blue"] == 0.0
    assert "Closed answer words (logit exactly 0 on every frame played" in eqa_table(closed)
    assert found["softplus"]["closed_answers"] == [] and found["softplus"]["answer_peak"]["blue"] > 0
    assert "Closed answer words" not in eqa_table(found["softplus"])
