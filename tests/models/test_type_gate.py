"""The 'type_gate' control (emml/models/type_gate.py): Eq. 4's gate from the dataset's word types, for questions
only; instructions keep the model's x_sent."""

import pytest
import torch

from emml.config.schema import TrainConfig
from emml.models import build_model
from emml.models.type_gate import TypeGate
from emml.tasks.language import Vocabulary, load_dataset

H, W, MAX_STEPS = 60, 108, 20


def _setup():
    ds = load_dataset("doom")
    vocab = Vocabulary.from_dataset(ds)
    return ds, vocab, TypeGate(vocab.words, ds)


def _tokens(vocab, texts, length=10):
    return torch.tensor([vocab.encode(t, length) for t in texts])


def test_a_question_opens_the_words_of_the_attribute_it_asks_for_at_the_models_strength():
    ds, vocab, gate = _setup()
    texts = ["what color is the torch", "which object is blue in color", "which is the smallest blue object"]
    x_sent = torch.rand(len(texts), len(vocab)) * 5
    g = gate(_tokens(vocab, texts), x_sent)
    colours = torch.tensor([w in ds.word_groups["colors"] for w in vocab.words])
    objects = torch.tensor([w in ds.word_groups["objects"] for w in vocab.words])
    top = x_sent.amax(dim=1)
    assert torch.equal(g[0], colours.float() * top[0])  # the queried object's own channel ('torch') closed
    for row in (1, 2):  # an object question: every colour channel closed, 'blue' included
        assert torch.equal(g[row], objects.float() * top[row])
    assert g[0, vocab.index("torch")] == 0 and g[1, vocab.index("blue")] == 0


def test_an_instruction_keeps_x_sent_and_padding_length_does_not_matter():
    ds, vocab, gate = _setup()
    texts = ["go to the torch", "go to the blue object", "what color is the pillar"]
    x_sent = torch.rand(len(texts), len(vocab))
    short, long = gate(_tokens(vocab, texts, 10), x_sent), gate(_tokens(vocab, texts, 16), x_sent)
    assert torch.equal(short, long)
    assert torch.equal(short[:2], x_sent[:2])  # 'object' in an instruction does not make it an object question
    assert not torch.equal(short[2], x_sent[2])


def test_the_model_reads_the_type_gate_in_eq4_and_plays_instructions_as_without_it():
    ds, vocab, gate = _setup()
    torch.manual_seed(0)
    plain = build_model("dual_attention", len(vocab), H, W, MAX_STEPS)
    gated = build_model("dual_attention", len(vocab), H, W, MAX_STEPS, control="type_gate")
    gated.load_state_dict(plain.state_dict())  # the gate's buffers are not in the state dict
    gated.type_gate = gate
    texts = ["what color is the torch", "go to the torch"]
    obs = {
        "image": torch.randint(0, 256, (1, 2, 3, H, W), dtype=torch.uint8),
        "tokens": _tokens(vocab, texts)[None],
        "task": torch.tensor([[1, 0]]),
        "time": torch.zeros(1, 2, dtype=torch.int64),
    }
    start = torch.ones(1, 2, dtype=torch.bool)
    with torch.no_grad():
        a, _ = plain(obs, plain.initial_state(2), start)
        b, _ = gated(obs, gated.initial_state(2), start)
    closed = torch.tensor([w not in ds.word_groups["colors"] for w in vocab.words])
    assert torch.all(b.answer_logits[0, 0, closed] == 0) and torch.all(b.answer_logits[0, 0, ~closed] > 0)  # Eq. 4-5
    assert torch.equal(a.answer_logits[0, 1], b.answer_logits[0, 1]) and torch.equal(a.logits[0, 1], b.logits[0, 1])
    assert not gated.reads_labels  # word types, no privileged labels


def test_the_control_is_refused_where_there_is_no_ga2_gate_or_no_words():
    with pytest.raises(ValueError, match="ga2=True"):
        build_model("da_no_ga2", 6, H, W, MAX_STEPS, control="type_gate")
    with pytest.raises(ValueError, match="type_gate"):
        build_model("ga", 6, H, W, MAX_STEPS, control="type_gate")
    model = build_model("dual_attention", 6, H, W, MAX_STEPS, control="type_gate")
    with pytest.raises(RuntimeError, match="load_model"):
        model.sentence_gate(torch.ones(1, 3, dtype=torch.int64))
    with pytest.raises(ValueError, match="evaluation control"):
        TrainConfig(aux=True, model_options={"control": "type_gate"}).validate()
