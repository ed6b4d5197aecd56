"""PPO's terms and update loop on small hand-made inputs, written to kill the mutants of emml/rl/ppo.py that the
other tests let survive (`make mutate`, docs/testing.md): the (T, B) shapes the trainer uses (not only flat
batches), entries exactly at a boundary (a ratio at the clip, one supervised entry, one negative cell), the value
clip below the old value, the error messages, the optimiser's settings, and what `ppo_update` reports and which
actors each minibatch replays."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest
import torch
import torch.nn.functional as F

import emml.rl.ppo as ppo
from emml.rl.ppo import (
    PPOConfig,
    answer_loss,
    aux_loss,
    entropy,
    explained_variance,
    make_optimizer,
    model_forward,
    move_logprob,
    policy_loss,
    ppo_losses,
    ppo_step,
    ppo_update,
    value_loss,
)
from emml.rl.rollout import RolloutBuffer
from tests.rl.test_ppo_losses import _batch, _ToyRecurrent

# --- the pure terms on (T, B) batches ------------------------------------------------------------------------------


def test_logprob_and_entropy_on_a_time_by_actor_batch():
    """(T, B, 4) logits as the update passes them: each entry its own row's log-softmax and entropy."""
    g = torch.Generator().manual_seed(1)
    logits = torch.randn(2, 3, 4, generator=g)
    actions = torch.tensor([[0, 3, 1], [2, 2, 0]])
    rows = [[torch.log_softmax(logits[t, b], 0)[actions[t, b]] for b in range(3)] for t in (0, 1)]
    want = torch.stack([torch.stack(row) for row in rows])
    torch.testing.assert_close(move_logprob(logits, actions), want)
    p = torch.softmax(logits, -1)
    torch.testing.assert_close(entropy(logits), -(p * p.log()).sum(-1))
    assert entropy(logits).shape == (2, 3)


def test_a_ratio_exactly_at_the_clip_is_not_clipped():
    """clipfrac counts |r - 1| > eps, strictly: an entry at r = 1 + eps exactly is inside."""
    new = torch.tensor([math.log(1.5), 0.0], dtype=torch.float64)
    clip = float(new[0].exp() - 1.0)  # |r - 1| of the first entry, to the bit
    _, _, clipfrac = policy_loss(new, torch.zeros(2, dtype=torch.float64), torch.ones(2, dtype=torch.float64), clip)
    assert clipfrac.item() == 0.0


def test_the_value_clip_holds_below_the_old_value_too():
    """new 0, old 1, clip 0.2: the clipped prediction is 0.8 (not 0); return 2: max((0-2)², (0.8-2)²)/2 = 2; return
    -0.5: max(0.25, 1.69)/2 = 0.845."""
    new, old = torch.tensor([0.0]), torch.tensor([1.0])
    assert value_loss(new, torch.tensor([2.0]), old, 0.2, clip=True).item() == pytest.approx(2.0)
    assert value_loss(new, torch.tensor([-0.5]), old, 0.2, clip=True).item() == pytest.approx(0.5 * 1.3**2)


def test_one_supervised_answer_is_its_cross_entropy():
    logits = torch.tensor([[2.0, 0.0, -1.0], [0.5, 0.5, 0.5]])
    loss = answer_loss(logits, torch.tensor([1, -1]))
    assert loss.item() == pytest.approx(-torch.log_softmax(logits[0], 0)[1].item())


def test_explained_variance_by_hand():
    """returns (1, 3, 5), values (1, 2, 3): Var[returns] = 8/3, Var[returns - values] = Var(0, 1, 2) = 2/3 (both
    over n): 1 - 1/4 = 0.75. Constant returns: nan."""
    assert explained_variance(torch.tensor([1.0, 2.0, 3.0]), torch.tensor([1.0, 3.0, 5.0])) == pytest.approx(0.75)
    assert math.isnan(explained_variance(torch.tensor([0.0, 1.0, 3.0]), torch.tensor([2.0, 2.0, 2.0])))


def test_two_advantages_are_normalised_too():
    """Normalisation needs two entries, not three: (1, 3) → (-1, 1) / sqrt(2) (their n - 1 std is sqrt(2))."""
    kw, _ = _batch(1, 2, 5)
    kw["advantages"], kw["answer_targets"] = torch.tensor([[1.0, 3.0]]), torch.tensor([[-1, 1]])
    kw["old_logprobs"] = move_logprob(kw["logits"], kw["actions"])  # r = 1: the loss is -mean(A)
    assert ppo_losses(PPOConfig(), **kw)["policy"].item() == pytest.approx(0.0, abs=1e-6)
    assert ppo_losses(PPOConfig(norm_adv=False), **kw)["policy"].item() == pytest.approx(-2.0)


def test_ppo_losses_clip_the_value_when_asked():
    kw, _ = _batch(3, 2, 5)
    want = value_loss(kw["values"], kw["returns"], kw["old_values"], 0.1, clip=True)
    assert want != value_loss(kw["values"], kw["returns"], kw["old_values"], 0.1, clip=False)
    torch.testing.assert_close(ppo_losses(PPOConfig(clip_coef=0.1, clip_vloss=True), **kw)["value"], want)


def test_ppo_losses_pass_the_aux_balance_and_name_a_missing_aux_head():
    kw, g = _batch(3, 2, 5)
    logits = torch.randn(3, 2, 5, 2, 2, generator=g)
    labels = torch.randint(0, 2, (3, 2, 5, 2, 2), dtype=torch.uint8, generator=g)
    out = ppo_losses(PPOConfig(aux_balance="word"), **kw, aux_logits=logits, aux_labels=labels)
    torch.testing.assert_close(out["aux"], aux_loss(logits, labels, torch.ones(5, dtype=torch.bool), "word"))
    with pytest.raises(ValueError, match="^aux_labels given but aux_logits is None$"):
        ppo_losses(PPOConfig(), **kw, aux_labels=labels)


def test_aux_loss_names_the_shapes_it_refuses():
    logits, labels = torch.zeros(2, 3, 2, 2), torch.zeros(2, 3, 2, 1)
    with pytest.raises(ValueError, match=r"^aux_logits \(2, 3, 2, 2\) vs labels \(2, 3, 2, 1\)$"):
        aux_loss(logits, labels, torch.ones(3, dtype=torch.bool))
    with pytest.raises(ValueError, match=r"^channel_mask must be \(3,\), got \(2,\)$"):
        aux_loss(logits, torch.zeros(2, 3, 2, 2), torch.ones(2, dtype=torch.bool))


def test_aux_loss_on_one_cell_is_its_cross_entropy():
    logit, label = torch.tensor([[[[0.3]]]]), torch.tensor([[[[1]]]], dtype=torch.uint8)
    assert aux_loss(logit, label, torch.tensor([True])).item() == pytest.approx(-F.logsigmoid(torch.tensor(0.3)).item())


def test_the_balanced_aux_loss_by_hand():
    """balance='word', one batch entry, three channels of four cells (logits 0: every cell's cross-entropy is log 2,
    except channel 0's first cell, logit 2):
      channel 0: labels (1, 1, 1, 0): positives mean (softplus(-2) + 2 log 2) / 3, one negative: log 2; halved
      channel 1: labels (1, 1, 1, 1): positives only: log 2 (one side, not halved)
      channel 2: labels (1, 0, 0, 0): one positive log 2, negatives log 2: log 2
    the mean over the three channels."""
    logits = torch.zeros(1, 3, 1, 4)
    logits[0, 0, 0, 0] = 2.0
    labels = torch.tensor([[[[1, 1, 1, 0]], [[1, 1, 1, 1]], [[1, 0, 0, 0]]]], dtype=torch.uint8)
    log2 = math.log(2)
    c0 = ((F.softplus(torch.tensor(-2.0)).item() + 2 * log2) / 3 + log2) / 2
    want = (c0 + log2 + log2) / 3
    assert aux_loss(logits, labels, torch.ones(3, dtype=torch.bool), "word").item() == pytest.approx(want, rel=1e-6)


# --- the update loop -----------------------------------------------------------------------------------------------


def test_model_forward_replays_through_the_model_and_returns_its_fields():
    seen = []

    class Model:
        def __call__(self, obs, state, starts):
            seen.append((obs, state, starts))
            return SimpleNamespace(logits=1, value=2), "next state"

    forward = model_forward(Model())
    assert forward("obs", "state", "starts") == {"logits": 1, "value": 2}
    assert seen == [("obs", "state", "starts")]


def _buffer(T: int = 4, B: int = 4, V: int = 3, seed: int = 0) -> tuple[_ToyRecurrent, RolloutBuffer]:
    """A toy recurrent model and a filled buffer whose image of actor e is the constant e (the actor is readable
    from any replayed observation); aux labels included."""
    torch.manual_seed(seed)
    model = _ToyRecurrent(V)
    buf = RolloutBuffer(T, B, {"image": ((3, 4, 4), torch.uint8), "aux": ((V, 2, 2), torch.uint8)})
    state = {"h": torch.zeros(B, 8)}
    buf.set_initial_state(state)
    with torch.no_grad():
        for t in range(T):
            obs = {
                "image": torch.arange(B, dtype=torch.uint8)[:, None, None, None].expand(B, 3, 4, 4).clone(),
                "aux": torch.randint(0, 2, (B, V, 2, 2), dtype=torch.uint8),
            }
            starts = torch.full((B,), t == 0)
            out = model({k: v[None] for k, v in obs.items()}, state, starts[None])
            dist = torch.distributions.Categorical(logits=out["logits"][0])
            a = dist.sample()
            buf.insert(t, obs, a, torch.randint(-1, V, (B,)), dist.log_prob(a), out["value"][0], torch.rand(B),
                       torch.full((B,), t == T - 1), starts)  # fmt: skip
    buf.compute_returns(torch.zeros(B), 0.99, 0.95)
    return model, buf


def test_each_epoch_replays_every_actor_once_in_disjoint_minibatches():
    model, buf = _buffer()
    calls = []

    def forward(obs, state, starts):
        calls.append(sorted(obs["image"][0, :, 0, 0, 0].tolist()))
        return model(obs, state, starts)

    cfg = PPOConfig(minibatches=2, epochs=3)
    ppo_update(forward, make_optimizer(model.parameters(), cfg), model.parameters(), buf, cfg)
    assert len(calls) == 6 and all(len(c) == 2 for c in calls)
    for epoch in range(3):
        assert sorted(calls[2 * epoch] + calls[2 * epoch + 1]) == [0, 1, 2, 3]
    calls.clear()
    one = PPOConfig(epochs=2)
    ppo_update(forward, make_optimizer(model.parameters(), one), model.parameters(), buf, one)
    assert calls == [[0, 1, 2, 3]] * 2  # the paper's single batch: the whole rollout each epoch


def test_minibatches_follow_the_generator_and_a_single_batch_draws_nothing():
    cfg = PPOConfig(minibatches=2, epochs=2)
    after = []
    for global_seed in (1, 2):
        model, buf = _buffer()
        torch.manual_seed(global_seed)  # the global generator differs; the update's own is the same
        gen = torch.Generator().manual_seed(7)
        ppo_update(model, make_optimizer(model.parameters(), cfg), model.parameters(), buf, cfg, generator=gen)
        after.append([p.detach().clone() for p in model.parameters()])
    assert all(torch.equal(a, b) for a, b in zip(*after))
    model, buf = _buffer()
    gen = torch.Generator().manual_seed(7)
    before = gen.get_state()
    ppo_update(model, make_optimizer(model.parameters(), PPOConfig()), model.parameters(), buf, PPOConfig(),
               generator=gen)  # fmt: skip
    assert torch.equal(gen.get_state(), before)


def test_the_update_reports_the_mean_of_its_steps(monkeypatch):
    """Each statistic is the mean over every optimiser step of what the step returned; explained variance is the
    rollout's."""
    steps = []
    original = ppo.ppo_step

    def recording(*args, **kwargs):
        steps.append(original(*args, **kwargs))
        return steps[-1]

    monkeypatch.setattr(ppo, "ppo_step", recording)
    model, buf = _buffer()
    cfg = PPOConfig(minibatches=2, epochs=2)
    stats = ppo_update(model, make_optimizer(model.parameters(), cfg), model.parameters(), buf, cfg)
    assert len(steps) == 4
    for k in ("policy", "value", "entropy", "answer", "aux", "total", "grad_norm"):
        assert stats[k] == pytest.approx(sum(float(s[k]) for s in steps) / 4, rel=1e-6), k
    assert stats["explained_variance"] == pytest.approx(explained_variance(buf.values, buf.returns))


def test_the_aux_channel_mask_and_use_aux_reach_the_loss():
    """One step on the whole batch: its aux term is aux_loss under the mask given, on the model as it was; with
    use_aux=False there is none; with the value clip on, the old values are read."""
    model, buf = _buffer()
    mask = torch.tensor([True, False, False])
    with torch.no_grad():
        out = model(buf.obs, buf.initial_state, buf.episode_starts)
        want = aux_loss(out["aux_logits"], buf.obs["aux"], mask)
    cfg = PPOConfig()
    terms = ppo_step(model, make_optimizer(model.parameters(), cfg), list(model.parameters()), buf,
                     buf.initial_state, cfg, mask)  # fmt: skip
    torch.testing.assert_close(terms["aux"], want)
    model, buf = _buffer()  # the same through the update loop: one epoch, one batch, the mean of one step
    stats = ppo_update(model, make_optimizer(model.parameters(), cfg), model.parameters(), buf, PPOConfig(epochs=1),
                       aux_channel_mask=mask)  # fmt: skip
    assert stats["aux"] == pytest.approx(want.item(), rel=1e-6)
    no_aux = ppo_update(model, make_optimizer(model.parameters(), cfg), model.parameters(), buf, cfg, use_aux=False)
    assert "aux" not in no_aux
    clipped = PPOConfig(clip_vloss=True)
    assert math.isfinite(
        ppo_update(model, make_optimizer(model.parameters(), clipped), model.parameters(), buf, clipped)["value"]
    )


def test_the_optimiser_is_adam_with_the_configs_settings():
    params = [torch.nn.Parameter(torch.zeros(2))]
    cfg = PPOConfig(lr=1.5e-4, adam_eps=2e-5)
    opt = make_optimizer(params, cfg)
    assert isinstance(opt, torch.optim.Adam)
    assert (opt.defaults["lr"], opt.defaults["eps"], opt.defaults["capturable"]) == (1.5e-4, 2e-5, False)
    assert make_optimizer(params, cfg, capturable=True).defaults["capturable"] is True
