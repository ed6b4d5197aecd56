"""The question-gate diagnostic (emml/eval/diagnose_gate.py): on hand-built gates whose answer is worked out by hand,
which questions have an unseen subject (from the dataset's splits), the gate's mass on the answer's attribute, and
the dead answer channels."""

import dataclasses

import numpy as np
import pytest
import torch

from emml.config.schema import DoomConfig, TrainConfig
from emml.eval.diagnose_gate import (
    attribute_channels,
    attribute_fraction,
    dead_channels,
    diagnose_gate,
    gate_metrics,
    record_gate,
    scalars,
    unseen_subjects,
)
from emml.models import build_model
from emml.tasks.language import Vocabulary, load_dataset
from tests.conftest import SMOKE

DS = load_dataset("doom")
WORDS = Vocabulary.from_dataset(DS).words
TRAIN = tuple(s.text for s in DS.select("eqa", "train"))
TEST = tuple(s.text for s in DS.select("eqa", "test"))


def _env(words=WORDS, **over) -> DoomConfig:
    return DoomConfig(**SMOKE, vocabulary=words, **over)


def _model(words=WORDS, name="dual_attention", **options):
    torch.manual_seed(0)
    cfg = _env(words)
    return build_model(name, len(words), cfg.height, cfg.width, cfg.max_steps, **options)


def _hand_gate(model, words, values):
    """Replace the model's x_sent by a hand-built one: ``values(question) -> {word: gate}``, 0 elsewhere, read back
    from the tokens (channel i is word i of ``words``)."""
    vocab = Vocabulary(words)

    def sentence_gate(tokens):
        rows = []
        for t in tokens.tolist():
            question = " ".join(vocab.words[i - 1] for i in t if i)
            g = torch.zeros(len(words))
            for w, v in values(question).items():
                g[vocab.index(w)] = v
            rows.append(g)
        return torch.stack(rows)

    model.sentence_gate = sentence_gate
    return model


def _colour_on_colours(question):
    """A colour question: 3 on 'red', 1 on 'torch' (3/4 on colours); an object question: 1 on 'torch', 1 on 'red',
    2 on 'what' (1/4 on objects). 'blue' is 0 everywhere, 'green' only on the training question about the pillar."""
    if question.startswith("what color"):
        gate = {"red": 3.0, "torch": 1.0}
        if question == "what color is the pillar":
            gate["green"] = 0.5
        return gate
    return {"torch": 1.0, "red": 1.0, "what": 2.0}


def test_the_unseen_subjects_are_the_test_questions_words_no_training_question_names():
    questions = unseen_subjects(DS, TRAIN, TEST)
    assert [q.text for q in questions] == list(TEST)  # every Doom test question names 'torch' or 'blue'
    by = {q.text: q for q in questions}
    assert by["what color is the torch"].unseen == ("torch",) and by["what color is the torch"].attribute == "color"
    assert by["which object is blue in color"].unseen == ("blue",)
    assert by["which object is blue in color"].attribute == "object"
    assert by["which is the largest blue object"].unseen == ("blue",)  # 'largest' is named by a training question


def test_a_subject_a_training_question_names_is_not_unseen():
    # a run that trained on the torch's colour question: its other torch questions' 'torch' is seen, 'short' too
    train = (*TRAIN, "what color is the torch")
    questions = unseen_subjects(DS, train, TEST)
    assert [q.text for q in questions] == [t for t in TEST if "blue" in t.split()]
    with pytest.raises(ValueError, match="'sgn' sentence; allowed: 'eqa'"):
        unseen_subjects(DS, TRAIN, ("go to the torch",))


def test_the_attribute_channels_are_the_answer_words_in_the_runs_channel_order():
    colours = attribute_channels(WORDS, DS, "color")
    objects = attribute_channels(WORDS, DS, "object")
    assert {w for w, c in zip(WORDS, colours) if c} == set(DS.word_groups["colors"])
    assert {w for w, c in zip(WORDS, objects) if c} == set(DS.word_groups["objects"])
    with pytest.raises(ValueError, match="answer attribute 'shape' is unknown; allowed: color, object, size"):
        attribute_channels(WORDS, DS, "shape")


def test_the_fraction_is_the_gates_mass_on_the_channels_over_its_total():
    on = np.array([True, False, True, False])
    assert attribute_fraction(np.array([1.0, 2.0, 3.0, 2.0]), on) == pytest.approx(4 / 8)
    assert attribute_fraction(np.zeros(4), on) == 0.0  # a gate shut on every channel opens no attribute
    with pytest.raises(ValueError, match=">= 0"):
        attribute_fraction(np.array([1.0, -1.0, 0.0, 0.0]), on)


def test_a_dead_channel_is_zero_on_every_question_and_an_answer_word():
    words = ("red", "blue", "what", "torch")
    gates = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 2.0]])
    assert dead_channels(gates, words, ("red", "blue", "torch")) == ["blue"]  # 'what' is no answer word
    assert dead_channels(gates, words, ("red", "blue", "what", "torch")) == ["blue", "what"]


def test_a_hand_built_gate_gives_its_hand_worked_figures():
    model = _hand_gate(_model(), WORDS, _colour_on_colours)
    result = diagnose_gate(model, _env())
    # 3 colour questions at 3/4 and 5 object questions at 1/4: mean (3 * 0.75 + 5 * 0.25) / 8 = 0.4375
    assert result["gate_on_color"] == pytest.approx(0.75)
    assert result["gate_on_object"] == pytest.approx(0.25)
    assert result["gate_on_attribute"] == pytest.approx(0.4375)
    assert result["gate_questions"]["what color is the torch"]["on_attribute"] == pytest.approx(0.75)
    # 'blue' and every answer word but red, torch and green is 0 on every question; green opens on a train question
    assert result["gate_dead_words"] == [
        w for w in WORDS if w in DS.answer_words() and w not in {"red", "torch", "green"}
    ]
    assert result["gate_dead"] == len(DS.answer_words()) - 3
    assert "blue" in result["gate_dead_words"] and "green" not in result["gate_dead_words"]


def test_the_channels_are_read_in_the_runs_vocabulary_order():
    """The same hand gate over a vocabulary in another order gives the same figures: channel i is the run's word i,
    not the dataset's."""
    shuffled = tuple(reversed(WORDS))
    model = _hand_gate(_model(shuffled), shuffled, _colour_on_colours)
    result = diagnose_gate(model, _env(shuffled))
    assert result["gate_on_color"] == pytest.approx(0.75) and result["gate_on_object"] == pytest.approx(0.25)


def test_the_figures_of_a_real_model_are_its_x_sent():
    model = _model()
    cfg = _env()
    result = diagnose_gate(model, cfg)
    vocab = Vocabulary(WORDS)
    tokens = torch.tensor([vocab.encode("what color is the torch", cfg.max_words)])
    with torch.no_grad():
        x_sent = model.text_encoder(tokens)[1][0].numpy()
    colours = attribute_channels(WORDS, DS, "color")
    expected = x_sent[colours].sum() / x_sent.sum()
    assert result["gate_questions"]["what color is the torch"]["on_attribute"] == pytest.approx(expected, rel=1e-5)
    assert 0.0 <= result["gate_on_attribute"] <= 1.0


@pytest.mark.parametrize(
    ("name", "options", "over"),
    [
        ("concat", {}, {}),  # no GA2 gate
        ("dual_attention", {"ga2": False}, {}),  # the w/o GA2 ablation
        ("dual_attention", {}, {"tasks": "sgn"}),  # not scored on EQA
    ],
)
def test_nothing_is_logged_without_a_gate_or_an_eqa_test_split(name, options, over):
    model = _model(name=name, **options)
    assert diagnose_gate(model, _env(**over)) == {}
    cfg = TrainConfig(model=name, env=_env(**over))
    assert gate_metrics(model, cfg) == {}


def test_the_trainer_logs_the_figures_under_diag_with_diagnostics_on_only():
    model = _hand_gate(_model(), WORDS, _colour_on_colours)
    cfg = TrainConfig(env=_env())
    logged = gate_metrics(model, cfg)
    assert logged["diag/gate_on_attribute"] == pytest.approx(0.4375)
    assert logged["diag/gate_dead"] == len(DS.answer_words()) - 3
    assert "diag/gate_on_size" not in logged  # no test question asks a size
    assert gate_metrics(model, dataclasses.replace(cfg, diagnose_episodes=0)) == {}


def _run_dir(tmp_path, name="dual_attention", finished=True, **options):
    """A run dir as the trainer leaves it: a checkpoint (its model, config and vocabulary) and a metrics mirror."""
    from emml.runs.checkpoint import save_checkpoint

    cfg = TrainConfig(model=name, env=_env(), model_options=options)
    model = _model(name=name, **options)
    rdir = tmp_path / "run"
    save_checkpoint(
        rdir / "checkpoint.pt",
        {"model": model.state_dict(), "config": cfg.to_dict(), "frames": 3200, "vocabulary": list(WORDS),
         "finished": finished},
    )  # fmt: skip
    (rdir / "metrics.csv").write_text("step,key,value\n1600,eval/eqa_test,0.25\n3200,eval/eqa_test,0.5\n")
    return rdir, model


def test_a_finished_run_gets_its_figures_appended_at_its_last_frame_once(tmp_path):
    from emml.runs.mirror import read_mirror

    rdir, model = _run_dir(tmp_path)
    before = (rdir / "metrics.csv").read_text()
    out = record_gate(rdir)
    expected = scalars(diagnose_gate(model, _env()))
    assert out["frames"] == 3200 and out["figures"] == pytest.approx(expected)
    assert set(out["written"]) == set(expected) >= {"diag/gate_on_attribute", "diag/gate_dead"}
    after = (rdir / "metrics.csv").read_text()
    assert after.startswith(before)  # append only: every line there before stays
    points = read_mirror(rdir / "metrics.csv")
    assert {k: v for s, k, v in points if k.startswith("diag/")} == pytest.approx(expected)
    assert {s for s, k, _ in points if k.startswith("diag/")} == {3200}
    again = record_gate(rdir / "checkpoint.pt")
    assert again["written"] == [] and (rdir / "metrics.csv").read_text() == after


def test_a_run_in_flight_or_without_a_gate_gets_nothing(tmp_path):
    rdir, _ = _run_dir(tmp_path, finished=False)
    before = (rdir / "metrics.csv").read_text()
    with pytest.raises(ValueError, match="not finished"):
        record_gate(rdir)
    assert (rdir / "metrics.csv").read_text() == before
    rdir, _ = _run_dir(tmp_path / "concat", name="concat")
    assert record_gate(rdir)["written"] == [] and (rdir / "metrics.csv").read_text() == before
