"""Fusion units of Chaplot et al. 2019 (arXiv 1902.01385): Dual-Attention Eq. 1-5, ablations, baselines."""

import math

import pytest
import torch

from emml.models.baselines import Concat, FiLM, GatedAttention, ImageOnly, Pacman, TextOnly
from emml.models.fusion import DualAttention, spatial_attention

# Vocabulary of the hand-made example: 0 pillar, 1 torch, 2 red, 3 green.
PILLAR, TORCH, RED, GREEN = range(4)


def _scene() -> torch.Tensor:
    """x_I (1, 4, 1, 2): a red pillar at column 0, a green torch at column 1."""
    x = torch.zeros(1, 4, 1, 2)
    x[0, PILLAR, 0, 0] = x[0, RED, 0, 0] = 1.0
    x[0, TORCH, 0, 1] = x[0, GREEN, 0, 1] = 1.0
    return x


def _question():
    """'Which color is the pillar?': BoW = {pillar}, x_sent attends to colour channels."""
    bow = torch.tensor([[1.0, 0.0, 0.0, 0.0]])
    sent = torch.tensor([[0.0, 0.0, 1.0, 1.0]])
    return bow, sent


def test_dual_attention_hand_example():
    x_i = _scene()
    bow, sent = _question()
    out = DualAttention(4, 1, 2)(x_i, bow, sent)
    # Eq. 1: words absent from the text zero their channel (checked through Eq. 2's input)
    x_ga1 = x_i * bow[:, :, None, None]
    assert torch.all(x_ga1[0, TORCH] == 0) and torch.all(x_ga1[0, GREEN] == 0)
    # Eq. 2: spatial map is a softmax over HxW of the pillar channel -> favours column 0
    p = math.e / (math.e + 1)
    torch.testing.assert_close(out.attention, torch.tensor([[[p, 1 - p]]]))
    assert out.attention.sum().item() == pytest.approx(1.0)
    torch.testing.assert_close(out.state, out.attention.reshape(1, 2))  # x_S = vec(x_spat)
    # Eq. 3-5: answer logits are the spatially-attended colour channels only
    torch.testing.assert_close(out.answer_logits, torch.tensor([[0.0, 0.0, p, 1 - p]]))
    x_ans = torch.softmax(out.answer_logits, dim=1)
    assert x_ans.sum().item() == pytest.approx(1.0)
    assert x_ans.argmax().item() == RED


def test_dual_attention_object_question_follows_gated_channels():
    """'Which object is green?': BoW = {green}, x_sent attends to object channels."""
    bow = torch.tensor([[0.0, 0.0, 0.0, 1.0]])
    sent = torch.tensor([[1.0, 1.0, 0.0, 0.0]])
    out = DualAttention(4, 1, 2)(_scene(), bow, sent)
    assert out.attention[0, 0, 1] > out.attention[0, 0, 0]
    assert torch.softmax(out.answer_logits, 1).argmax().item() == TORCH


def test_absent_word_channel_does_not_move_attention():
    x_i = _scene()
    bow, sent = _question()
    fusion = DualAttention(4, 1, 2)
    base = fusion(x_i, bow, sent).attention
    changed = x_i.clone()
    changed[0, GREEN] = torch.tensor([[5.0, -3.0]])  # 'green' is not in the text
    torch.testing.assert_close(fusion(changed, bow, sent).attention, base)


def test_dual_attention_has_no_parameters():
    assert list(DualAttention(4, 1, 2).parameters()) == []


def test_ablation_no_ga1_uses_all_channels():
    x_i = _scene()
    bow, sent = _question()
    out = DualAttention(4, 1, 2, ga1=False)(x_i, None, sent)
    torch.testing.assert_close(out.attention, torch.full((1, 1, 2), 0.5))  # both columns sum to 2


def test_ablation_no_ga2_answers_from_x_sa():
    x_i = _scene()
    bow, _ = _question()
    out = DualAttention(4, 1, 2, ga2=False)(x_i, bow, None)
    p = math.e / (math.e + 1)
    torch.testing.assert_close(out.answer_logits, torch.tensor([[p, 1 - p, p, 1 - p]]))


def test_ablation_no_sa_state_is_gated_image():
    x_i = _scene()
    bow, sent = _question()
    fusion = DualAttention(4, 1, 2, spatial=False)
    out = fusion(x_i, bow, sent)
    assert out.attention is None
    assert fusion.state_dim == 4 * 1 * 2
    torch.testing.assert_close(out.state, (x_i * bow[:, :, None, None]).flatten(1))
    torch.testing.assert_close(out.answer_logits, torch.tensor([[0.0, 0.0, 1.0, 1.0]]))


@pytest.fixture
def inputs():
    torch.manual_seed(0)
    v, h, w = 5, 2, 3
    x_i = torch.rand(4, v, h, w)
    bow = (torch.rand(4, v) > 0.5).float()
    sent = torch.rand(4, v)
    return x_i, bow, sent


@pytest.mark.parametrize(
    "cls,expected",
    [
        (TextOnly, lambda x, b, s: torch.cat([b, s], 1)),
        (ImageOnly, lambda x, b, s: x.flatten(1)),
        (Concat, lambda x, b, s: torch.cat([x.flatten(1), b, s], 1)),
        (GatedAttention, lambda x, b, s: (x * s[:, :, None, None]).flatten(1)),
    ],
)
def test_baseline_states_and_answer_head(cls, expected, inputs):
    x_i, bow, sent = inputs
    fusion = cls(5, 2, 3)
    out = fusion(x_i, bow, sent)
    ref = expected(x_i, bow, sent)
    assert out.state.shape[1] == fusion.state_dim
    torch.testing.assert_close(out.state, ref)
    # answer = softmax(ReLU(Linear(x_S))): logits are the ReLU output
    torch.testing.assert_close(out.answer_logits, torch.relu(fusion.answer.linear(ref)))
    assert out.attention is None


def test_film_state(inputs):
    x_i, bow, sent = inputs
    fusion = FiLM(5, 2, 3)
    out = fusion(x_i, bow, sent)
    gamma, beta = fusion.gamma(sent), fusion.beta(sent)
    ref = (gamma[:, :, None, None] * x_i + beta[:, :, None, None]).flatten(1)
    torch.testing.assert_close(out.state, ref)


def test_pacman_attention_over_frames(inputs):
    torch.manual_seed(1)
    _, _, sent = inputs
    frames = torch.rand(4, 5, 5, 2, 3)
    fusion = Pacman(5, 2, 3)
    weights, proj = fusion.frame_attention(frames, sent)
    assert weights.shape == (4, 5)
    torch.testing.assert_close(weights.sum(1), torch.ones(4))
    out = fusion(frames, None, sent)
    ref = (weights[:, :, None] * frames.flatten(2)).sum(1)
    torch.testing.assert_close(out.state, ref)
    attended = (weights[:, :, None] * proj).sum(1)
    torch.testing.assert_close(out.answer_logits, fusion.classifier(torch.cat([attended, sent], 1)))


def test_pacman_attends_to_matching_frame():
    fusion = Pacman(2, 1, 1)
    with torch.no_grad():
        fusion.project.weight.copy_(torch.eye(2) * 10)
        fusion.project.bias.zero_()
    frames = torch.tensor([[[1.0, 0.0], [0.0, 1.0], [1.0, 0.0]]]).reshape(1, 3, 2, 1, 1)
    weights, _ = fusion.frame_attention(frames, torch.tensor([[0.0, 1.0]]))
    assert weights.argmax().item() == 1


def test_state_scale_gives_the_policy_a_mean_one_map():
    """x_S = h·w · vec(x_spat): entries average 1 whatever the grid (a plain softmax averages 1/(h·w))."""
    x_i = torch.rand(3, 4, 2, 5)
    bow, sent = torch.ones(3, 4), torch.ones(3, 4)
    plain = DualAttention(4, 2, 5)(x_i, bow, sent)
    scaled = DualAttention(4, 2, 5, state_scale=True)(x_i, bow, sent)
    torch.testing.assert_close(scaled.state, plain.state * 10)
    torch.testing.assert_close(scaled.state.mean(1), torch.ones(3))
    torch.testing.assert_close(scaled.attention, plain.attention)  # Eq. 2-5 unchanged
    torch.testing.assert_close(scaled.answer_logits, plain.answer_logits)


def test_state_temperature_hands_the_policy_a_sharper_map_without_gradient():
    """Opt-in `state_temperature`: x_S = h·w · softmax(scores / t) with the gradient stopped; x_spat, the answer and
    the gradients every other output sends into the detectors are those of the default model."""
    torch.manual_seed(0)
    x_i = torch.rand(3, 4, 2, 5, requires_grad=True)
    bow, sent = torch.ones(3, 4), torch.ones(3, 4)
    plain = DualAttention(4, 2, 5, state_scale=True)(x_i, bow, sent)
    sharp = DualAttention(4, 2, 5, state_scale=True, state_temperature=0.25)(x_i, bow, sent)
    scores = x_i.detach().sum(1).reshape(3, 10)  # Eq. 1-2 with every word in the BoW
    torch.testing.assert_close(sharp.state, torch.softmax(scores / 0.25, dim=1) * 10)
    assert (sharp.state.max(1).values > plain.state.max(1).values).all()  # sharper: the top cell gains
    torch.testing.assert_close(sharp.attention, plain.attention)  # Eq. 2-5 unchanged
    torch.testing.assert_close(sharp.answer_logits, plain.answer_logits)
    assert not sharp.state.requires_grad  # no policy or value gradient reaches the detectors through x_S
    assert plain.state.requires_grad
    (grad_plain,) = torch.autograd.grad(plain.answer_logits.sum(), x_i)
    (grad_sharp,) = torch.autograd.grad(sharp.answer_logits.sum(), x_i)
    torch.testing.assert_close(grad_sharp, grad_plain)  # the answer's gradient into the detectors is unchanged


def test_answer_grad_gate_keeps_the_answer_loss_out_of_the_detectors():
    """`answer_grad='gate'` (issue 34): the same values; Eq. 5's answer reaches x_sent as before and x_I not at all,
    while the state (the policy's path into the detectors) keeps its gradient."""
    x_i = _scene().requires_grad_()
    bow = torch.tensor([[0.0, 1.0, 1.0, 0.0]])
    sent = torch.tensor([[0.0, 0.0, 1.0, 1.0]], requires_grad=True)
    plain, gate = DualAttention(4, 1, 2)(x_i, bow, sent), DualAttention(4, 1, 2, answer_grad="gate")(x_i, bow, sent)
    torch.testing.assert_close(gate.answer_logits, plain.answer_logits)
    torch.testing.assert_close(gate.state, plain.state)
    grad_i, grad_sent = torch.autograd.grad(plain.answer_logits[0, 2], (x_i, sent))
    assert grad_i.abs().sum() > 0  # the paper's unit: the answer trains the detectors
    gate_i, gate_sent = torch.autograd.grad(gate.answer_logits[0, 2], (x_i, sent), allow_unused=True)
    assert gate_i is None or gate_i.abs().sum() == 0
    torch.testing.assert_close(gate_sent, grad_sent)
    (state_i,) = torch.autograd.grad(gate.state[0, 0], x_i)
    assert state_i.abs().sum() > 0  # the policy still trains them through x_S


def test_answer_grad_centered_moves_a_detector_where_the_map_attends_never_a_whole_channel():
    """`answer_grad='centered'` (issue 48): the same values; the answer's gradient into x_I sums to zero over the
    cells of every frame and channel (no common shift: what pinned the No Aux conv), is the paper's gradient less
    its cell mean, and still reaches x_sent as before; a flat map passes nothing into x_I."""
    x_i = torch.rand(3, 4, 2, 3, requires_grad=True)
    bow = torch.tensor([[0.0, 1.0, 1.0, 0.0]]).repeat(3, 1)
    sent = torch.rand(3, 4, requires_grad=True)
    plain = DualAttention(4, 2, 3)(x_i, bow, sent)
    centered = DualAttention(4, 2, 3, answer_grad="centered")(x_i, bow, sent)
    torch.testing.assert_close(centered.answer_logits, plain.answer_logits, rtol=0, atol=0)
    torch.testing.assert_close(centered.state, plain.state, rtol=0, atol=0)
    weights = torch.randn(3, 4)
    grad_i, grad_sent = torch.autograd.grad((plain.answer_logits * weights).sum(), (x_i, sent))
    cent_i, cent_sent = torch.autograd.grad((centered.answer_logits * weights).sum(), (x_i, sent))
    torch.testing.assert_close(cent_i.sum(dim=(2, 3)), torch.zeros(3, 4), rtol=0, atol=1e-6)
    assert cent_i.abs().sum() > 0  # what moves one cell against another still reaches the detectors
    # through Eq. 3 the paper's gradient less its cell mean; through Eq. 2's softmax, already centred
    direct = torch.autograd.grad(
        (spatial_attention(x_i, plain.attention.detach()) * sent[:, :, None, None] * weights[:, :, None, None]).sum(),
        x_i,
    )[0]
    torch.testing.assert_close(cent_i - grad_i, -direct.mean(dim=(2, 3), keepdim=True).expand_as(direct))
    torch.testing.assert_close(cent_sent, grad_sent)
    flat = torch.full((1, 4, 2, 3), 0.5, requires_grad=True)  # a flat x_I: a flat map, a uniform answer gradient
    out = DualAttention(4, 2, 3, answer_grad="centered")(flat, bow[:1], sent[:1].detach())
    (flat_grad,) = torch.autograd.grad(out.answer_logits[0, 2], flat)
    torch.testing.assert_close(flat_grad, torch.zeros_like(flat_grad), rtol=0, atol=1e-7)


def test_answer_gate_frames_keeps_the_answer_loss_to_the_gate_until_the_run_has_trained_them():
    """`answer_gate_frames` (issue 48, the warm-up): before N frames the answer reaches x_sent and not x_I, as
    'gate'; from N frames on it reaches x_I as `answer_grad` says; the values never change. The model hears the
    frames through `EmmlModel.at_frames` (the trainer's call before each rollout)."""
    x_i = _scene().requires_grad_()
    bow = torch.tensor([[0.0, 1.0, 1.0, 0.0]])
    sent = torch.tensor([[0.0, 0.0, 1.0, 1.0]], requires_grad=True)
    unit, plain = DualAttention(4, 1, 2, answer_gate_frames=100), DualAttention(4, 1, 2)
    for frames, reaches in ((0, False), (99, False), (100, True), (5000, True)):
        unit.at_frames(frames)
        out = unit(x_i, bow, sent)
        torch.testing.assert_close(out.answer_logits, plain(x_i, bow, sent).answer_logits, rtol=0, atol=0)
        grad_i, grad_sent = torch.autograd.grad(out.answer_logits[0, 2], (x_i, sent), allow_unused=True)
        assert (grad_i is not None and grad_i.abs().sum() > 0) == reaches, frames
        assert grad_sent.abs().sum() > 0


def test_answer_gate_frames_is_checked_named_and_told_by_the_model():
    from emml.config.profiles import profile_config
    from emml.models import build_model, model_config
    from emml.runs.naming import run_name

    cfg = profile_config("smoke", "easy", {"model_options.answer_gate_frames": 300_000})
    assert run_name(cfg) == "dual_attention-easy-noaux-warm300000-s0-smoke"
    model = build_model("dual_attention", 22, 36, 36, 30, answer_gate_frames=300_000)
    assert model.fusion.warming
    model.at_frames(300_000)
    assert not model.fusion.warming
    plain = build_model("concat", 22, 36, 36, 30)
    plain.at_frames(10)  # a run without the warm-up: never warming
    assert not plain.fusion.warming
    for name, over, message in (
        ("dual_attention", {"answer_gate_frames": -1}, r"answer_gate_frames=-1 must be a whole number of frames from"),
        (
            "dual_attention",
            {"answer_gate_frames": 10, "answer_grad": "gate"},
            r"answer_grad='gate' keeps it there throughout \(allowed with it: 0\)",
        ),
        ("text_only", {"answer_gate_frames": 10}, r"model 'text_only' \(TextOnly\) has no answer that reads x_I"),
    ):
        with pytest.raises(ValueError, match=message):
            model_config(name, **over)


def test_eq1_over_the_content_words_drops_the_function_words_channels_from_the_attention():
    """`eq1_words='content'` (issue 34): a function word's channel, firing on the wrong object, moves the paper's
    x_spat (Eq. 1-2) and not the content-word one's; the mask must be set (or restored) before use."""
    function = 4  # a fifth channel, the word 'what': its detector fires on the torch (column 1)
    x_i = torch.zeros(1, 5, 1, 2)
    x_i[0, :4] = _scene()[0]
    x_i[0, function, 0, 1] = 3.0
    bow = torch.tensor([[1.0, 0.0, 0.0, 0.0, 1.0]])  # 'what ... pillar'
    sent = torch.tensor([[0.0, 0.0, 1.0, 1.0, 0.0]])
    paper = DualAttention(5, 1, 2)(x_i, bow, sent)
    assert paper.attention[0, 0, 1] > paper.attention[0, 0, 0]  # pulled onto the torch by 'what'
    unit = DualAttention(5, 1, 2, eq1_words="content")
    with pytest.raises(RuntimeError, match="needs the run's words"):
        unit(x_i, bow, sent)
    unit.read_words(torch.tensor([1.0, 1.0, 1.0, 1.0, 0.0]))
    content = unit(x_i, bow, sent)
    assert content.attention[0, 0, 0] > content.attention[0, 0, 1]  # on the pillar, as the content word says
    torch.testing.assert_close(content.attention, DualAttention(5, 1, 2)(x_i, bow * unit.eq1_mask, sent).attention)
    restored = DualAttention(5, 1, 2, eq1_words="content")
    restored.load_state_dict(unit.state_dict())  # a checkpoint carries the mask
    torch.testing.assert_close(restored(x_i, bow, sent).attention, content.attention)
    with pytest.raises(RuntimeError, match="eq1_words='all'"):
        DualAttention(5, 1, 2).read_words(torch.ones(5))
    assert "eq1_mask" not in DualAttention(5, 1, 2).state_dict()  # the paper's unit: checkpoints unchanged


def test_a_baseline_answer_channel_dead_under_relu_learns_again_under_softplus():
    """The appendix's head softmax(ReLU(Linear(x_S))): a logit whose Linear output is negative on every frame gets no
    gradient from the answer loss (its word is never answered again); under the opt-in softplus it does. The option
    is the baselines' own, named in the run, checked by name, and draws no parameter (a seed's weights unchanged)."""
    from emml.config.profiles import profile_config
    from emml.models import build_model, model_config
    from emml.runs.naming import run_name

    def seeded(**options):
        torch.manual_seed(0)
        return build_model("concat", 5, 36, 36, 30, **options)

    paper, soft = seeded(), seeded(answer_activation="softplus")
    for a, b in zip(paper.state_dict().values(), soft.state_dict().values(), strict=True):
        torch.testing.assert_close(a, b)
    x_s = torch.rand(8, paper.fusion.state_dim)
    for model in (paper, soft):
        head = model.fusion.answer
        with torch.no_grad():
            head.linear.bias[2] = -10.0  # answer word 2: below 0 on every input
        loss = torch.nn.functional.cross_entropy(head(x_s), torch.full((8,), 2))
        (grad,) = torch.autograd.grad(loss, head.linear.bias)
        assert (grad[2] == 0) == (model is paper), head.activation
    named = profile_config("smoke", "easy", {"model": "concat", "model_options.answer_activation": "softplus"})
    assert run_name(named) == "concat-easy-noaux-headsoftplus-s0-smoke"
    with pytest.raises(ValueError, match=r"answer_activation='tanh' is not allowed; choose one of 'relu', 'softplus'"):
        model_config("concat", answer_activation="tanh")
    with pytest.raises(ValueError, match=r"answer_activation"):
        model_config("dual_attention", answer_activation="softplus")  # Eq. 5 is not this head
