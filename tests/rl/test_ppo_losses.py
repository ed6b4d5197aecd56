"""PPO loss terms (PPO Eq. 7), supervised heads, config validation, update smoke test."""

import math

import pytest
import torch
import torch.nn.functional as F
from hypothesis import given, settings
from hypothesis import strategies as st

from emml.rl.ppo import (
    PPOConfig,
    answer_loss,
    aux_loss,
    entropy,
    make_optimizer,
    move_logprob,
    policy_loss,
    ppo_losses,
    ppo_update,
    value_loss,
)
from emml.rl.rollout import RolloutBuffer


def test_policy_loss_clipping_hand_batch():
    clip = 0.2
    old = torch.zeros(4)
    # ratios: 1.5 (A>0, clipped: no grad), 0.5 (A>0, unclipped), 0.5 (A<0, clipped: no grad), 1.1 (A<0, inside)
    ratios = torch.tensor([1.5, 0.5, 0.5, 1.1])
    new = ratios.log().requires_grad_(True)
    adv = torch.tensor([1.0, 2.0, -1.0, -1.0])
    loss, kl, clipfrac = policy_loss(new, old, adv, clip)
    # objective per entry: min(r*A, clip(r)*A): 1.2, 1.0, -0.8, -1.1
    torch.testing.assert_close(loss, -torch.tensor([1.2, 1.0, -0.8, -1.1]).mean())
    assert clipfrac.item() == pytest.approx(3 / 4)  # |r-1| > 0.2 for 1.5, 0.5, 0.5
    expected_kl = ((ratios - 1) - ratios.log()).mean()
    torch.testing.assert_close(kl, expected_kl)
    loss.backward()
    grad = new.grad
    assert grad[0] == 0 and grad[2] == 0  # clipped entries give no gradient
    # d/dlogp of -(r*A)/N = -r*A/N
    torch.testing.assert_close(grad[1], torch.tensor(-0.5 * 2.0 / 4))
    torch.testing.assert_close(grad[3], torch.tensor(-1.1 * -1.0 / 4))


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-5, 5), min_size=1, max_size=16), st.floats(0.05, 0.5))
def test_policy_loss_at_ratio_one_is_minus_mean_advantage(advs, clip):
    adv = torch.tensor(advs)
    logp = torch.randn(len(advs))
    loss, kl, clipfrac = policy_loss(logp, logp.clone(), adv, clip)
    assert loss.item() == pytest.approx(-adv.mean().item(), abs=1e-5)
    assert kl.item() == pytest.approx(0.0, abs=1e-7) and clipfrac.item() == 0.0


def test_value_loss_plain_and_clipped():
    new = torch.tensor([1.0, 3.0])
    ret = torch.tensor([0.0, 0.0])
    old = torch.tensor([1.0, 1.0])
    assert value_loss(new, ret, old, 0.2, clip=False).item() == pytest.approx(0.5 * (1 + 9) / 2)
    # clipped prediction for entry 1 is 1.2 -> (1.2)^2 < 9 so max keeps 9; entry 0 unchanged
    assert value_loss(new, ret, old, 0.2, clip=True).item() == pytest.approx(0.5 * (1 + 9) / 2)
    new2 = torch.tensor([1.0, 1.5])
    ret2 = torch.tensor([1.0, 3.0])  # clipped pred 1.2 is farther from 3 than 1.5 -> 1.8^2
    assert value_loss(new2, ret2, old, 0.2, clip=True).item() == pytest.approx(0.5 * (0 + 1.8**2) / 2)


def test_entropy_and_logprob():
    logits = torch.tensor([[0.0, 0.0, 0.0, 0.0], [100.0, 0.0, 0.0, 0.0]])
    ent = entropy(logits)
    assert ent[0].item() == pytest.approx(math.log(4)) and ent[1].item() == pytest.approx(0.0, abs=1e-6)
    lp = move_logprob(logits, torch.tensor([2, 0]))
    torch.testing.assert_close(lp, torch.tensor([-math.log(4), 0.0]))


def test_answer_loss_ignores_minus_one():
    g = torch.Generator().manual_seed(0)
    logits = torch.randn(3, 2, 5, generator=g, requires_grad=True)
    targets = torch.tensor([[-1, 2], [4, -1], [-1, 0]])
    loss = answer_loss(logits, targets)
    keep = targets.reshape(-1) >= 0
    ref = F.cross_entropy(logits.reshape(-1, 5)[keep], targets.reshape(-1)[keep])
    torch.testing.assert_close(loss, ref)
    loss.backward()
    assert logits.grad.reshape(-1, 5)[~keep].abs().sum() == 0
    # no supervision at all: exact zero, graph kept
    logits2 = torch.randn(2, 5, requires_grad=True)
    zero = answer_loss(logits2, torch.full((2,), -1))
    assert zero.item() == 0.0 and zero.requires_grad
    zero.backward()
    assert torch.equal(logits2.grad, torch.zeros(2, 5))


def test_aux_loss_ignores_masked_channels():
    g = torch.Generator().manual_seed(0)
    logits = torch.randn(2, 3, 4, 2, 3, generator=g, requires_grad=True)  # (T, B, V, h, w)
    labels = torch.randint(0, 2, (2, 3, 4, 2, 3), dtype=torch.uint8, generator=g)
    mask = torch.tensor([True, False, True, False])
    loss = aux_loss(logits, labels, mask)
    flipped = labels.clone()
    flipped[:, :, 1] = 1 - flipped[:, :, 1]
    flipped[:, :, 3] = 1
    torch.testing.assert_close(aux_loss(logits, flipped, mask), loss)
    ref = F.binary_cross_entropy_with_logits(logits[:, :, mask], labels[:, :, mask].float())
    torch.testing.assert_close(loss, ref)
    loss.backward()
    assert logits.grad[:, :, ~mask].abs().sum() == 0
    none = aux_loss(logits, labels, torch.zeros(4, dtype=torch.bool))
    assert none.item() == 0.0 and none.requires_grad


def test_aux_loss_balanced_per_word_weighs_a_words_few_cells_as_the_rest():
    # one channel, 8 cells, 1 labelled: 'none' is the mean of the 8; 'word' the mean of the 1 and of the 7, halved
    logits = torch.tensor([2.0, -1.0, 0.5, 0.0, -3.0, 1.0, -0.5, 0.25]).reshape(1, 1, 1, 2, 4).requires_grad_()
    labels = torch.zeros(1, 1, 1, 2, 4, dtype=torch.uint8)
    labels[..., 0, 1] = 1
    bce = F.binary_cross_entropy_with_logits(logits, labels.float(), reduction="none").flatten()
    on = labels.flatten().bool()
    mask = torch.tensor([True])
    torch.testing.assert_close(aux_loss(logits, labels, mask, "none"), bce.mean())
    balanced = aux_loss(logits, labels, mask, "word")
    torch.testing.assert_close(balanced, (bce[on].mean() + bce[~on].mean()) / 2)
    # the labelled cell gets 1/2 of the weight (not 1/8): its gradient 4x the paper's mean
    balanced.backward()
    g_word = logits.grad.flatten()[on].clone()
    logits.grad = None
    aux_loss(logits, labels, mask, "none").backward()
    torch.testing.assert_close(g_word, 4 * logits.grad.flatten()[on])
    # a channel with no labelled cell in the batch: the mean over its cells; masked channels: no loss, no gradient
    two = torch.zeros(1, 1, 3, 2, 4)
    two[:, :, 0] = logits.detach()
    lab = torch.zeros(1, 1, 3, 2, 4, dtype=torch.uint8)
    lab[:, :, 0] = labels[:, :, 0]
    bce0 = F.binary_cross_entropy_with_logits(two[:, :, 1], torch.zeros(1, 1, 2, 4))
    torch.testing.assert_close(
        aux_loss(two, lab, torch.tensor([True, True, False]), "word"), (balanced.detach() + bce0) / 2
    )
    with pytest.raises(ValueError, match="balance='class' is not allowed; choose one of 'none', 'word'"):
        aux_loss(logits, labels, mask, "class")


def _batch(T: int = 3, B: int = 2, V: int = 5) -> tuple[dict, torch.Generator]:
    """One minibatch's inputs of `ppo_losses` (no aux), and the generator to draw more from."""
    g = torch.Generator().manual_seed(0)
    kw = dict(
        logits=torch.randn(T, B, 4, generator=g),
        values=torch.randn(T, B, generator=g),
        actions=torch.randint(0, 4, (T, B), generator=g),
        old_logprobs=torch.randn(T, B, generator=g) - 1.5,
        old_values=torch.randn(T, B, generator=g),
        advantages=torch.randn(T, B, generator=g),
        returns=torch.randn(T, B, generator=g),
        answer_logits=torch.randn(T, B, V, generator=g),
        answer_targets=torch.tensor([[-1, 1], [2, -1], [-1, -1]]),
    )
    return kw, g


def test_ppo_losses_total_combines_terms():
    cfg = PPOConfig(ent_coef=0.1, vf_coef=0.3, answer_coef=0.7, aux_coef=2.0, norm_adv=False)
    T, B, V = 3, 2, 5
    kw, g = _batch(T, B, V)
    out = ppo_losses(cfg, **kw)
    assert "aux" not in out
    expected = out["policy"] - 0.1 * out["entropy"] + 0.3 * out["value"] + 0.7 * out["answer"]
    torch.testing.assert_close(out["total"], expected)
    aux_logits = torch.randn(T, B, V, 2, 2, generator=g)
    labels = torch.randint(0, 2, (T, B, V, 2, 2), dtype=torch.uint8, generator=g)
    out2 = ppo_losses(cfg, **kw, aux_logits=aux_logits, aux_labels=labels)
    torch.testing.assert_close(out2["total"], expected + 2.0 * out2["aux"])
    torch.testing.assert_close(out2["aux"], F.binary_cross_entropy_with_logits(aux_logits, labels.float()))


def test_ppo_losses_read_nothing_back_from_the_device():
    """The losses have no data-dependent shape or branch, so a GPU update needs no host sync and can be captured
    (issue 19): dynamo traces them as one graph. Fails on a masked selection (`bool(keep.any())`, `x[mask]`)."""
    cfg = PPOConfig()
    T, B, V = 3, 2, 5
    kw, g = _batch(T, B, V)
    kw.update(
        aux_logits=torch.randn(T, B, V, 2, 2, generator=g),
        aux_labels=torch.randint(0, 2, (T, B, V, 2, 2), dtype=torch.uint8, generator=g),
        aux_channel_mask=torch.tensor([True, False, True, True, False]),
    )
    torch._dynamo.reset()
    traced = torch.compile(lambda **k: ppo_losses(cfg, **k), fullgraph=True, backend="eager")
    got, want = traced(**kw), ppo_losses(cfg, **kw)
    for k in want:
        torch.testing.assert_close(got[k], want[k])


@pytest.mark.parametrize(
    "field,value",
    [
        ("clip_coef", 0.0),
        ("clip_coef", 1.5),
        ("gamma", 1.1),
        ("gae_lambda", -0.1),
        ("epochs", 0),
        ("minibatches", 2.5),
        ("lr", 0.0),
        ("ent_coef", -1.0),
        ("max_grad_norm", float("nan")),
        ("norm_adv", 1),
        ("adam_eps", 0.0),
        ("aux_coef", -0.5),
    ],
)
def test_config_validate_names_field(field, value):
    assert PPOConfig().validate() is not None
    with pytest.raises(ValueError, match=field):
        PPOConfig(**{field: value}).validate()


class _ToyRecurrent(torch.nn.Module):
    """Tiny GRU agent with the project's output interface, for the update smoke test."""

    def __init__(self, V=3):
        super().__init__()
        self.enc = torch.nn.Linear(3, 8)
        self.cell = torch.nn.GRUCell(8, 8)
        self.pi = torch.nn.Linear(8, 4)
        self.v = torch.nn.Linear(8, 1)
        self.ans = torch.nn.Linear(8, V)
        self.aux = torch.nn.Linear(8, V * 2 * 2)
        self.V = V

    def forward(self, obs, state, episode_starts):
        h = state["h"]
        outs = []
        for t in range(obs["image"].shape[0]):
            h = h * (~episode_starts[t]).float()[:, None]
            x = obs["image"][t].float().mean(dim=(-1, -2)) / 255.0  # (b, 3)
            h = self.cell(torch.relu(self.enc(x)), h)
            outs.append(h)
        hs = torch.stack(outs)
        T, b = hs.shape[:2]
        return {
            "logits": self.pi(hs),
            "value": self.v(hs).squeeze(-1),
            "answer_logits": self.ans(hs),
            "aux_logits": self.aux(hs).view(T, b, self.V, 2, 2),
        }


@pytest.mark.parametrize("minibatches", [1, 2])
def test_ppo_update_smoke(minibatches):
    torch.manual_seed(0)
    T, B, V = 6, 4, 3
    model = _ToyRecurrent(V)
    cfg = PPOConfig(minibatches=minibatches).validate()
    opt = make_optimizer(model.parameters(), cfg)
    buf = RolloutBuffer(T, B, {"image": ((3, 4, 4), torch.uint8), "aux": ((V, 2, 2), torch.uint8)})
    state = {"h": torch.zeros(B, 8)}
    buf.set_initial_state(state)
    with torch.no_grad():
        for t in range(T):
            obs = {
                "image": torch.randint(0, 256, (B, 3, 4, 4), dtype=torch.uint8),
                "aux": torch.randint(0, 2, (B, V, 2, 2), dtype=torch.uint8),
            }
            starts = torch.full((B,), t == 0)
            out = model({k: v[None] for k, v in obs.items()}, state, starts[None])
            dist = torch.distributions.Categorical(logits=out["logits"][0])
            a = dist.sample()
            buf.insert(
                t,
                obs,
                a,
                torch.randint(-1, V, (B,)),
                dist.log_prob(a),
                out["value"][0],
                torch.rand(B),
                torch.full((B,), t == T - 1),
                starts,
            )
    buf.compute_returns(torch.zeros(B), cfg.gamma, cfg.gae_lambda)
    before = [p.detach().clone() for p in model.parameters()]
    stats = ppo_update(model, opt, model.parameters(), buf, cfg, aux_channel_mask=torch.tensor([True, True, False]))
    assert {
        "policy",
        "value",
        "entropy",
        "answer",
        "aux",
        "total",
        "approx_kl",
        "clipfrac",
        "grad_norm",
        "explained_variance",
    } <= set(stats)
    assert all(math.isfinite(v) for k, v in stats.items() if k != "explained_variance")
    assert any(not torch.equal(b, p) for b, p in zip(before, model.parameters(), strict=True))
    with pytest.raises(ValueError, match="minibatches"):
        ppo_update(model, opt, model.parameters(), buf, PPOConfig(minibatches=3), use_aux=False)
