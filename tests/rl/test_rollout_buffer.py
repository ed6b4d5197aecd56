"""RolloutBuffer: dtypes, exact storage, initial state and returns."""

import pytest
import torch

from emml.rl.rollout import RolloutBuffer, compute_gae

T, B, H, W, L, V = 4, 2, 6, 8, 5, 7
SHAPES = {
    "image": ((3, H, W), torch.uint8),
    "tokens": ((L,), torch.int64),
    "task": ((), torch.int64),
    "time": ((), "int64"),
    "aux": ((V, 2, 3), torch.uint8),
}


def _obs(g):
    return {
        "image": torch.randint(0, 256, (B, 3, H, W), dtype=torch.uint8, generator=g),
        "tokens": torch.randint(0, 10, (B, L), generator=g),
        "task": torch.randint(0, 2, (B,), generator=g),
        "time": torch.randint(0, 210, (B,), generator=g),
        "aux": torch.randint(0, 2, (B, V, 2, 3), dtype=torch.uint8, generator=g),
    }


def test_stores_exactly_what_was_inserted_and_keeps_uint8():
    g = torch.Generator().manual_seed(0)
    buf = RolloutBuffer(T, B, SHAPES)
    assert buf.obs["image"].dtype == torch.uint8 and buf.obs["aux"].dtype == torch.uint8
    assert buf.obs["time"].dtype == torch.int64
    assert buf.answer_targets.eq(-1).all()
    steps = []
    for t in range(T):
        obs = _obs(g)
        rec = dict(
            obs=obs,
            action=torch.randint(0, 4, (B,), generator=g),
            answer_target=torch.tensor([-1, t]),
            logprob=torch.randn(B, generator=g, requires_grad=True),
            value=torch.randn(B, generator=g),
            reward=torch.randn(B, generator=g),
            done=torch.tensor([t == 1, False]),
            episode_start=torch.tensor([t == 2, t == 0]),
        )
        buf.insert(t, **rec)
        steps.append(rec)
    assert not buf.logprobs.requires_grad
    for t, rec in enumerate(steps):
        for k in SHAPES:
            assert torch.equal(buf.obs[k][t], rec["obs"][k])
        assert torch.equal(buf.actions[t], rec["action"])
        assert torch.equal(buf.answer_targets[t], rec["answer_target"])
        assert torch.equal(buf.logprobs[t], rec["logprob"].detach())
        assert torch.equal(buf.values[t], rec["value"])
        assert torch.equal(buf.rewards[t], rec["reward"])
        assert torch.equal(buf.dones[t], rec["done"])
        assert torch.equal(buf.episode_starts[t], rec["episode_start"])
    # images never converted: no float tensor in obs storage
    assert all(not v.is_floating_point() for v in buf.obs.values())

    last = torch.tensor([0.5, -0.5])
    buf.compute_returns(last, 0.99, 0.95)
    adv, ret = compute_gae(buf.rewards, buf.values, buf.dones, last, 0.99, 0.95)
    assert torch.equal(buf.advantages, adv) and torch.equal(buf.returns, ret)


def test_rejects_float_images_wrong_keys_and_shapes():
    g = torch.Generator().manual_seed(1)
    buf = RolloutBuffer(T, B, SHAPES)
    obs = _obs(g)
    args = dict(
        action=torch.zeros(B, dtype=torch.long),
        answer_target=torch.full((B,), -1),
        logprob=torch.zeros(B),
        value=torch.zeros(B),
        reward=torch.zeros(B),
        done=torch.zeros(B, dtype=torch.bool),
        episode_start=torch.zeros(B, dtype=torch.bool),
    )
    with pytest.raises(TypeError):
        buf.insert(0, {**obs, "image": obs["image"].float() / 255}, **args)
    with pytest.raises(KeyError):
        buf.insert(0, {k: v for k, v in obs.items() if k != "aux"}, **args)
    with pytest.raises(ValueError):
        buf.insert(0, {**obs, "tokens": obs["tokens"][:, :2]}, **args)
    with pytest.raises(IndexError):
        buf.insert(T, obs, **args)


def test_initial_state_is_a_detached_clone():
    buf = RolloutBuffer(T, B, {"task": ((), torch.int64)})
    h = torch.randn(B, 128, requires_grad=True)
    frames = torch.randint(0, 256, (B, 4, 3, H, W), dtype=torch.uint8)
    buf.set_initial_state({"h": h, "frames": frames})
    with torch.no_grad():
        h.add_(1.0)
    frames.zero_()
    assert not torch.equal(buf.initial_state["h"], h) and not buf.initial_state["h"].requires_grad
    assert buf.initial_state["frames"].dtype == torch.uint8 and buf.initial_state["frames"].any()
    with pytest.raises(ValueError):
        buf.set_initial_state({"h": torch.zeros(B + 1, 3)})


def test_frames_are_stored_in_the_conv_stacks_layout():
    """The (T·B, 3, H, W) batch the update feeds the conv stack is channels_last as stored (a view, no copy)."""
    g = torch.Generator().manual_seed(0)
    buf = RolloutBuffer(T, B, SHAPES)
    frames = [_obs(g)["image"] for _ in range(T)]
    for t, frame in enumerate(frames):
        buf._put("image", buf.obs["image"], frame, t)
    batch = buf.obs["image"].flatten(0, 1)
    assert batch.is_contiguous(memory_format=torch.channels_last)
    assert batch.data_ptr() == buf.obs["image"].data_ptr()
    assert torch.equal(batch, torch.stack(frames).flatten(0, 1))
    assert buf.obs["aux"].is_contiguous()  # labels are not frames
