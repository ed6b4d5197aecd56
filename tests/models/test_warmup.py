"""The No Aux warm-up, one rule for every model (issue 61): `ModelConfig.answer_gate_frames` = N keeps the answer
loss's gradient off the image encoder for the run's first N frames, then lets it through, for every model whose
answer reads x_I; where there is no GA2 gate the answer loss keeps training the text side and the head."""

import pytest
import torch
import torch.nn.functional as F

from emml.models import MODELS, build_model

V, H, W, MAX_STEPS, N = 6, 60, 108, 20, 100

WARMED = [name for name, spec in MODELS.items() if spec.fusion.answer_warmup]


def _obs(t=3, b=2, seed=0):
    g = torch.Generator().manual_seed(seed)
    tokens = torch.randint(1, V + 1, (t, b, 4), generator=g)
    tokens[..., -1] = 0
    return {
        "image": torch.randint(0, 256, (t, b, 3, H, W), dtype=torch.uint8, generator=g),
        "tokens": tokens,
        "task": torch.ones(t, b, dtype=torch.long),  # EQA: the steps the answer loss trains on
        "time": torch.randint(0, MAX_STEPS + 1, (t, b), generator=g),
    }


def _grads(model, loss_of) -> dict[str, torch.Tensor]:
    """Each parameter's gradient of ``loss_of(output)`` (zeros where none reaches it)."""
    t, b = 3, 2
    starts = torch.zeros(t, b, dtype=torch.bool)
    starts[0] = True
    out, _ = model(_obs(t, b), model.initial_state(b), starts)
    loss = loss_of(out)
    params = dict(model.named_parameters())
    if not loss.requires_grad:  # nothing trainable reaches it (Dual-Attention w/o GA2 in its warm-up)
        return {k: torch.zeros_like(p) for k, p in params.items()}
    grads = torch.autograd.grad(loss, list(params.values()), allow_unused=True)
    return {k: torch.zeros_like(p) if g is None else g for (k, p), g in zip(params.items(), grads, strict=True)}


def _answer_loss(out):
    target = torch.arange(out.answer_logits[..., 0].numel()).reshape(out.answer_logits.shape[:2]) % V
    return F.cross_entropy(out.answer_logits.flatten(0, 1), target.flatten())


def _norm(grads, prefix) -> float:
    return float(sum(g.abs().sum() for k, g in grads.items() if k.startswith(prefix)))


def test_every_model_of_the_paper_whose_answer_reads_the_image_takes_the_warm_up():
    """Text only is the one model whose answer reads no image (its conv is trained by the aux loss alone)."""
    assert set(MODELS) - set(WARMED) == {"text_only"}


@pytest.mark.parametrize("name", WARMED)
def test_the_answer_loss_reaches_the_conv_only_after_the_warm_up(name):
    """For N frames no gradient of the answer loss reaches the image encoder (conv1-3); from N frames on it does. The
    answer's values are those of the model without the warm-up throughout."""
    torch.manual_seed(0)
    model = build_model(name, V, H, W, MAX_STEPS, answer_gate_frames=N)
    torch.manual_seed(0)
    plain = build_model(name, V, H, W, MAX_STEPS)
    assert model.fusion.warming
    for frames, reaches in ((0, False), (N - 1, False), (N, True), (10 * N, True)):
        model.at_frames(frames)
        assert model.fusion.warming is not reaches
        grads = _grads(model, _answer_loss)
        conv = _norm(grads, "image_encoder.")
        assert (conv > 0) is reaches, (name, frames, conv)
        with torch.no_grad():
            ours = model(_obs(), model.initial_state(2), torch.ones(3, 2, dtype=torch.bool))[0].answer_logits
            paper = plain(_obs(), plain.initial_state(2), torch.ones(3, 2, dtype=torch.bool))[0].answer_logits
        torch.testing.assert_close(ours, paper, rtol=0, atol=0)


@pytest.mark.parametrize("name", [n for n in WARMED if n != "da_no_ga2"])
def test_during_the_warm_up_the_answer_loss_trains_the_text_side_and_the_head(name):
    """Where the model has a GA2 gate it is x_sent's encoder; where it has none (the baselines), the text side it reads
    (x_sent, FiLM's gamma and beta) and its answer head. Dual-Attention w/o GA2's answer reads x_I alone: in its
    warm-up the answer loss trains nothing."""
    model = build_model(name, V, H, W, MAX_STEPS, answer_gate_frames=N)
    grads = _grads(model, _answer_loss)
    assert _norm(grads, "image_encoder.") == 0
    fusion = model.fusion
    if fusion.uses_sent:
        assert _norm(grads, "text_encoder.") > 0, name
    for prefix in ("fusion.answer.", "fusion.gamma.", "fusion.beta.", "fusion.project.", "fusion.classifier."):
        if any(k.startswith(prefix) for k in grads):
            assert _norm(grads, prefix) > 0, (name, prefix)


def test_dual_attention_without_ga2_answers_from_the_conv_alone_and_its_warm_up_trains_nothing():
    model = build_model("da_no_ga2", V, H, W, MAX_STEPS, answer_gate_frames=N)
    assert _norm(_grads(model, _answer_loss), "") == 0
    model.at_frames(N)
    assert _norm(_grads(model, _answer_loss), "image_encoder.") > 0


@pytest.mark.parametrize("name", WARMED)
def test_the_policy_still_trains_the_conv_during_the_warm_up(name):
    """Only the answer is kept off x_I: the actor and critic read x_S, which reaches the conv as always."""
    model = build_model(name, V, H, W, MAX_STEPS, answer_gate_frames=N)
    grads = _grads(model, lambda out: out.logits.square().sum() + out.value.square().sum())
    assert _norm(grads, "image_encoder.") > 0, name


@pytest.mark.parametrize("name", WARMED)
def test_the_warm_up_keys_a_captured_graph(name):
    """The switch is Python-level: a CUDA graph captured inside the warm-up is not replayed after it."""
    model = build_model(name, V, H, W, MAX_STEPS, answer_gate_frames=N)
    before = model.trace_key()
    model.at_frames(N)
    assert model.trace_key() != before
