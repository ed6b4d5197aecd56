"""Packed runs (emml/rl/packed.py): N models stacked under vmap give each run's own outputs and own PPO update."""

from __future__ import annotations

import copy

import pytest
import torch

from emml.models import MODELS, build_model
from emml.rl.packed import (
    StackedModels,
    clip_grad_norm_per_run,
    load_optimizer_state,
    optimizer_state,
    packed_ppo_update,
)
from emml.rl.ppo import PPOConfig, make_optimizer, ppo_update
from emml.rl.rollout import RolloutBuffer

V, H, W, L, STEPS = 12, 60, 108, 6, 20
TOL = dict(rtol=1e-4, atol=1e-5)


def _models(name: str, n: int) -> list:
    out = []
    for seed in range(n):
        torch.manual_seed(seed)
        out.append(build_model(name, V, H, W, STEPS))
    return out


def _obs(t: int, b: int, gen: torch.Generator, aux_shape=None) -> dict:
    obs = {
        "image": torch.randint(0, 256, (t, b, 3, H, W), dtype=torch.uint8, generator=gen),
        "tokens": torch.randint(1, V + 1, (t, b, L), generator=gen),
        "task": torch.randint(0, 2, (t, b), generator=gen),
        "time": torch.randint(0, STEPS, (t, b), generator=gen),
    }
    obs["tokens"][..., -2:] = 0  # right padding, as the env writes it
    if aux_shape is not None:
        obs["aux"] = torch.randint(0, 2, (t, b, *aux_shape), dtype=torch.uint8, generator=gen)
    return obs


def _run(obs: dict, r: int, n: int) -> dict:
    """Run r's actors of an interleaved batch (actor j = b * n + r)."""
    return {k: v[:, r::n] for k, v in obs.items()}


@pytest.mark.parametrize("name", list(MODELS))
def test_stacked_forward_equals_each_plain_model(name):
    n, t, b = 3, 4, 2
    models = _models(name, n)
    stacked = StackedModels(models)
    gen = torch.Generator().manual_seed(1)
    obs = _obs(t, n * b, gen)
    starts = torch.rand(t, n * b, generator=gen) < 0.3
    state = stacked.initial_state(n * b)
    state["h"] = torch.randn(state["h"].shape, generator=gen)
    with torch.no_grad():
        out, new = stacked(obs, state, starts)
        for r, model in enumerate(models):
            model.text_cache = None
            ref, ref_state = model(_run(obs, r, n), {k: v[r::n] for k, v in state.items()}, starts[:, r::n])
            for field in ("logits", "value", "answer_logits", "aux_logits", "attention"):
                got, want = getattr(out, field), getattr(ref, field)
                if want is None:
                    assert got is None
                    continue
                torch.testing.assert_close(got[:, r::n], want, **TOL)
            for k in ref_state:
                torch.testing.assert_close(new[k][r::n], ref_state[k], **TOL)


def test_unstack_and_load_run_round_trip():
    models = _models("dual_attention", 2)
    stacked = StackedModels(models)
    for r, model in enumerate(models):
        plain = stacked.unstack(r)
        for (k, a), b in zip(plain.state_dict().items(), model.state_dict().values()):
            assert torch.equal(a, b), k
    stacked.load_run(0, models[1].state_dict())
    assert all(torch.equal(a, b) for a, b in zip(stacked.unstack(0).parameters(), models[1].parameters()))
    # the models given are not tied to the stack
    with torch.no_grad():
        next(iter(stacked.stacked.values())).add_(1.0)
    assert torch.equal(
        stacked.unstack(1).state_dict()["image_encoder.conv1.weight"], models[1].image_encoder.conv1.weight
    )


def test_stacking_refuses_different_architectures():
    with pytest.raises(ValueError, match="architecture"):
        StackedModels([build_model("ga", V, H, W, STEPS), build_model("dual_attention", V, H, W, STEPS)])


def test_per_run_clip_matches_clip_grad_norm():
    torch.manual_seed(0)
    plain = [[torch.nn.Parameter(torch.randn(3, 4)), torch.nn.Parameter(torch.randn(5))] for _ in range(3)]
    stacked = [torch.nn.Parameter(torch.stack([p[i].detach() for p in plain])) for i in range(2)]
    grads = [[torch.randn(3, 4) * (r + 0.1), torch.randn(5) * (r + 0.1)] for r in range(3)]
    for r, ps in enumerate(plain):
        for p, g in zip(ps, grads[r]):
            p.grad = g.clone()
    for i, p in enumerate(stacked):
        p.grad = torch.stack([grads[r][i] for r in range(3)])
    norms = clip_grad_norm_per_run(stacked, 0.5)
    for r, ps in enumerate(plain):
        want = torch.nn.utils.clip_grad_norm_(ps, 0.5)
        torch.testing.assert_close(norms[r], want)
        for i, p in enumerate(ps):
            torch.testing.assert_close(stacked[i].grad[r], p.grad)


def _filled_buffer(t: int, b: int, gen: torch.Generator, aux_shape) -> RolloutBuffer:
    obs = _obs(t, b, gen, aux_shape)
    shapes = {k: (tuple(v.shape[2:]), v.dtype) for k, v in obs.items()}
    buf = RolloutBuffer(t, b, shapes)
    for k, v in obs.items():
        buf.obs[k].copy_(v)
    buf.actions.copy_(torch.randint(0, 4, (t, b), generator=gen))
    buf.logprobs.copy_(-torch.rand(t, b, generator=gen) - 1.0)
    buf.values.copy_(torch.randn(t, b, generator=gen))
    buf.rewards.copy_(torch.randn(t, b, generator=gen))
    buf.dones.copy_(torch.rand(t, b, generator=gen) < 0.1)
    buf.episode_starts[1:] = buf.dones[:-1]
    buf.episode_starts[0] = True
    buf.answer_targets.copy_(torch.where(torch.rand(t, b, generator=gen) < 0.5, torch.randint(0, V, (t, b)), -1))
    buf.compute_returns(torch.randn(b, generator=gen), 0.99, 0.95)
    return buf


@pytest.mark.parametrize("name", ["dual_attention", "pacman"])
def test_packed_update_equals_separate_updates(name):
    n, t, b = 2, 6, 2
    models = _models(name, n)
    stacked = StackedModels(models)
    cfg = PPOConfig(epochs=2)
    aux_shape = (V, *models[0].grid)
    buf = _filled_buffer(t, n * b, torch.Generator().manual_seed(3), aux_shape)
    state = stacked.initial_state(n * b)
    buf.set_initial_state(state)
    mask = torch.ones(V, dtype=torch.bool)
    mask[-1] = False  # a word without aux labels
    optimizer = make_optimizer(stacked.parameters_in_order(), cfg)
    stats = packed_ppo_update(stacked, optimizer, buf, cfg, mask)
    for r, model in enumerate(models):
        run = RolloutBuffer(t, b, {k: (tuple(v.shape[2:]), v.dtype) for k, v in buf.obs.items()})
        for k, v in buf.obs.items():
            run.obs[k].copy_(v[:, r::n])
        for k in (
            "actions",
            "logprobs",
            "values",
            "rewards",
            "dones",
            "episode_starts",
            "answer_targets",
            "advantages",
            "returns",
        ):
            getattr(run, k).copy_(getattr(buf, k)[:, r::n])
        run.set_initial_state({k: v[r::n] for k, v in state.items()})
        opt = make_optimizer(model.parameters(), cfg)

        def forward(o, s, e, model=model):
            return vars(model(o, s, e)[0])

        want = ppo_update(forward, opt, model.parameters(), run, cfg, mask)
        for k, v in want.items():
            assert stats[r][k] == pytest.approx(v, rel=1e-4, abs=1e-5), k
        for (pname, a), b_ in zip(stacked.unstack(r).named_parameters(), model.parameters()):
            torch.testing.assert_close(a, b_, **TOL, msg=pname)
        # run r's optimizer state, in the plain format, is the plain optimizer's
        saved = optimizer_state(optimizer, r)
        for index, entry in opt.state_dict()["state"].items():
            for k, v in entry.items():
                torch.testing.assert_close(saved["state"][index][k], v, **TOL)
    # and it loads back into a fresh stacked optimizer's slot
    fresh = make_optimizer(stacked.parameters_in_order(), cfg)
    load_optimizer_state(fresh, 1, optimizer_state(optimizer, 1))
    got = optimizer_state(fresh, 1)
    for index, entry in optimizer_state(optimizer, 1)["state"].items():
        for k, v in entry.items():
            torch.testing.assert_close(got["state"][index][k], v)


def test_packed_update_refuses_minibatches():
    stacked = StackedModels(_models("ga", 2))
    buf = _filled_buffer(2, 4, torch.Generator().manual_seed(0), None)
    buf.set_initial_state(stacked.initial_state(4))
    cfg = PPOConfig(minibatches=2)
    with pytest.raises(ValueError, match="minibatches"):
        packed_ppo_update(stacked, make_optimizer(stacked.parameters(), cfg), buf, cfg, use_aux=False)


def test_vmappable_model_equals_the_plain_one():
    torch.manual_seed(0)
    model = build_model("dual_attention", V, H, W, STEPS)
    fast = copy.deepcopy(model).vmappable()
    obs = _obs(3, 4, torch.Generator().manual_seed(2))
    starts = torch.zeros(3, 4, dtype=torch.bool)
    model.text_cache = None
    a, _ = model(obs, model.initial_state(4), starts)
    b, _ = fast(obs, fast.initial_state(4), starts)
    for field in ("logits", "value", "answer_logits", "aux_logits", "attention"):
        torch.testing.assert_close(getattr(a, field), getattr(b, field), **TOL)
