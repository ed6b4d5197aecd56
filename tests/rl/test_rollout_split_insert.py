"""RolloutBuffer as the double-buffered sampler writes it: a step in two halves (`insert_policy` when the policy acts,
`insert_outcome` when the env answers), one env group (a slice of the actors) at a time.

Each test states by hand what every cell must hold, so that a half that writes the wrong field, the wrong actors or
the wrong step, or a check with a shifted boundary, fails here (issue 66: the mutants left in the split insert)."""

import re

import pytest
import torch

from emml.rl.rollout import RolloutBuffer, _as_dtype

T, B, H, W = 3, 4, 2, 3
SHAPES = {"image": ((3, H, W), torch.uint8), "tokens": ((2,), torch.int64), "task": ((), "int64")}
GROUPS = (slice(0, 2), slice(2, 4))


def _policy(t: int, g: int) -> dict:
    """Distinct, hand-checkable values for step t of group g (2 actors): every field differs from every other."""
    base = 100 * t + 10 * g
    return dict(
        obs={
            "image": torch.full((2, 3, H, W), base % 256, dtype=torch.uint8),
            "tokens": torch.tensor([[base, base + 1], [base + 2, base + 3]]),
            "task": torch.tensor([g, 1 - g]),
        },
        action=torch.tensor([t % 4, (t + 1) % 4]),
        answer_target=torch.tensor([base + 5, -1]),
        logprob=torch.tensor([-0.5 - t, -1.5 - g]),
        value=torch.tensor([float(base), float(base) + 0.25]),
        episode_start=torch.tensor([t == 0, g == 1]),
    )


def _outcome(t: int, g: int) -> dict:
    return dict(reward=torch.tensor([t + 0.5 * g, -(t + 1.0)]), done=torch.tensor([t == 1, g == 0 and t == 2]))


def _fill_as_the_sampler_does() -> RolloutBuffer:
    """Acting for group 1 while group 0 simulates: policy(t, 0), policy(t, 1), then each group's outcome of t."""
    buf = RolloutBuffer(T, B, SHAPES)
    for t in range(T):
        for g, envs in enumerate(GROUPS):
            p = _policy(t, g)
            buf.insert_policy(
                t, p["obs"], p["action"], p["answer_target"], p["logprob"], p["value"], p["episode_start"], envs=envs
            )
        for g, envs in enumerate(GROUPS):
            buf.insert_outcome(t, **_outcome(t, g), envs=envs)
    return buf


def test_each_half_lands_in_its_own_fields_of_its_own_actors_and_step():
    buf = _fill_as_the_sampler_does()
    for t in range(T):
        for g, envs in enumerate(GROUPS):
            p, o = _policy(t, g), _outcome(t, g)
            for key in SHAPES:
                assert torch.equal(buf.obs[key][t, envs], p["obs"][key]), (t, g, key)
            assert buf.actions[t, envs].tolist() == p["action"].tolist()
            assert buf.answer_targets[t, envs].tolist() == p["answer_target"].tolist()
            assert buf.logprobs[t, envs].tolist() == p["logprob"].tolist()
            assert buf.values[t, envs].tolist() == p["value"].tolist()
            assert buf.episode_starts[t, envs].tolist() == p["episode_start"].tolist()
            assert buf.rewards[t, envs].tolist() == o["reward"].tolist()
            assert buf.dones[t, envs].tolist() == o["done"].tolist()


def test_the_halves_in_groups_store_what_one_whole_insert_per_step_stores():
    split, whole = _fill_as_the_sampler_does(), RolloutBuffer(T, B, SHAPES)
    for t in range(T):
        halves = [(_policy(t, g), _outcome(t, g)) for g in range(2)]
        obs = {k: torch.cat([p["obs"][k] for p, _ in halves]) for k in SHAPES}
        cat = {
            f: torch.cat([p[f] for p, _ in halves])
            for f in ("action", "answer_target", "logprob", "value", "episode_start")
        }
        out = {f: torch.cat([o[f] for _, o in halves]) for f in ("reward", "done")}
        whole.insert(t, obs, **cat, **out)
    for name in ("actions", "answer_targets", "logprobs", "values", "rewards", "dones", "episode_starts"):
        assert torch.equal(getattr(split, name), getattr(whole, name)), name
    for key in SHAPES:
        assert torch.equal(split.obs[key], whole.obs[key]), key


def test_a_half_leaves_every_other_cell_as_it_was():
    buf = RolloutBuffer(T, B, SHAPES)
    p = _policy(1, 1)
    buf.insert_policy(
        1, p["obs"], p["action"], p["answer_target"], p["logprob"], p["value"], p["episode_start"], envs=GROUPS[1]
    )
    # the outcome's fields untouched by the policy's half
    assert not buf.rewards.any() and not buf.dones.any()
    # the other group and the other steps still hold the storage's initial values
    others = torch.ones(T, B, dtype=torch.bool)
    others[1, 2:] = False
    assert buf.answer_targets[others].eq(-1).all() and buf.answer_targets[1, 2:].tolist() == [115, -1]
    for name in ("actions", "logprobs", "values", "episode_starts"):
        assert not getattr(buf, name)[others].any(), name
    assert not buf.obs["image"][others].any() and buf.obs["image"][1, 2:].eq(110).all()

    buf.insert_outcome(2, torch.tensor([7.0, 8.0]), torch.tensor([True, False]), envs=GROUPS[0])
    assert buf.rewards[2].tolist() == [7.0, 8.0, 0.0, 0.0] and buf.dones[2].tolist() == [True, False, False, False]
    assert not buf.rewards[:2].any() and not buf.dones[:2].any()
    assert buf.values[2].eq(0).all() and buf.actions[2].eq(0).all()  # the outcome's half writes nothing of the policy's


@pytest.mark.parametrize("t, ok", [(-1, False), (0, True), (T - 1, True), (T, False)])
def test_each_half_takes_exactly_the_steps_of_the_rollout(t, ok):
    buf = RolloutBuffer(T, B, SHAPES)
    p, o = _policy(0, 0), _outcome(0, 0)

    def policy():
        buf.insert_policy(
            t, p["obs"], p["action"], p["answer_target"], p["logprob"], p["value"], p["episode_start"], envs=GROUPS[0]
        )

    def outcome():
        buf.insert_outcome(t, **o, envs=GROUPS[0])

    for half in (policy, outcome):
        if ok:
            half()
        else:
            with pytest.raises(IndexError, match=re.escape(f"t={t} outside [0, {T})")):
                half()
    if ok:
        assert buf.values[t, :2].tolist() == p["value"].tolist() and buf.rewards[t, :2].tolist() == [0.0, -1.0]
    else:
        assert not buf.values.any() and not buf.rewards.any()  # nothing written before the refusal


def test_refusals_name_the_field_and_both_shapes_or_key_sets():
    buf = RolloutBuffer(T, B, SHAPES)
    p = _policy(0, 0)
    args = [p["action"], p["answer_target"], p["logprob"], p["value"], p["episode_start"]]
    with pytest.raises(
        KeyError, match=re.escape("obs keys ['image', 'task'] != buffer keys ['image', 'task', 'tokens']")
    ):
        buf.insert_policy(0, {k: v for k, v in p["obs"].items() if k != "tokens"}, *args, envs=GROUPS[0])
    with pytest.raises(KeyError, match="extra"):
        buf.insert_policy(0, {**p["obs"], "extra": p["obs"]["task"]}, *args, envs=GROUPS[0])
    with pytest.raises(ValueError, match=re.escape("value: expected shape (2,), got (3,)")):
        buf.insert_policy(0, p["obs"], *args[:3], torch.zeros(3), args[4], envs=GROUPS[0])
    with pytest.raises(ValueError, match=re.escape("done: expected shape (2,), got (4,)")):
        buf.insert_outcome(0, torch.zeros(2), torch.zeros(4, dtype=torch.bool), envs=GROUPS[1])
    with pytest.raises(TypeError, match=re.escape("action: cannot store floating torch.float32 into torch.int64")):
        buf.insert_policy(0, p["obs"], p["action"].float(), *args[1:], envs=GROUPS[0])
    with pytest.raises(TypeError, match=re.escape("obs['image']: cannot store floating")):
        buf.insert_policy(0, {**p["obs"], "image": p["obs"]["image"].float()}, *args, envs=GROUPS[0])
    # integers into float storage are exact and allowed (a reward of 1 from an env)
    buf.insert_outcome(0, torch.tensor([1, 0]), torch.tensor([False, True]), envs=GROUPS[1])
    assert buf.rewards[0].tolist() == [0.0, 0.0, 1.0, 0.0] and buf.rewards.dtype == torch.float32


def test_values_with_autograd_history_are_stored_without_it():
    buf = RolloutBuffer(T, B, SHAPES)
    p = _policy(0, 1)
    value = p["value"].clone().requires_grad_(True) * 2  # a non-leaf, as the critic's output is
    logprob = p["logprob"].clone().requires_grad_(True) + 0
    buf.insert_policy(0, p["obs"], p["action"], p["answer_target"], logprob, value, p["episode_start"], envs=GROUPS[1])
    assert not buf.values.requires_grad and not buf.logprobs.requires_grad
    assert buf.values[0, 2:].tolist() == [20.0, 20.5]


def test_fresh_storage_its_types_and_what_it_refuses():
    buf = RolloutBuffer(T, B, SHAPES, device="cpu")
    assert buf.device == torch.device("cpu") and (buf.num_steps, buf.num_envs) == (T, B)
    ints, floats, flags = (
        ("actions", "answer_targets"),
        ("logprobs", "values", "rewards", "advantages", "returns"),
        ("dones", "episode_starts"),
    )
    for name in ints + floats + flags:
        tensor = getattr(buf, name)
        assert tensor.shape == (T, B), name
        assert tensor.dtype == (torch.int64 if name in ints else torch.float32 if name in floats else torch.bool)
        assert tensor.eq(-1 if name == "answer_targets" else 0).all(), name
    assert buf.obs["task"].dtype == torch.int64 and buf.obs["image"].shape == (T, B, 3, H, W)
    assert buf.initial_state == {}
    for steps, envs in ((0, B), (T, 0), (-1, B)):
        with pytest.raises(ValueError, match=re.escape(f"got {steps}, {envs}")):
            RolloutBuffer(steps, envs, SHAPES)
    assert _as_dtype("uint8") is torch.uint8 and _as_dtype(torch.bool) is torch.bool
    for bad in ("uint9", "Tensor"):  # not a name in torch; a name in torch that is no dtype
        with pytest.raises(TypeError, match=re.escape(f"unknown dtype {bad!r}")):
            _as_dtype(bad)


def test_returns_take_the_last_value_as_floats_without_its_history():
    buf = _fill_as_the_sampler_does()
    last = torch.tensor([1.0, 2.0, 3.0, 4.0], requires_grad=True)
    buf.compute_returns(last * 1, 0.5, 1.0)
    assert not buf.advantages.requires_grad and not buf.returns.requires_grad
    # the last step by hand: actor 3 did not end its episode at t=2, so A = r + γ·V(s_T) − V(s_2)
    r, v = buf.rewards[2, 3].item(), buf.values[2, 3].item()
    assert buf.advantages[2, 3].item() == pytest.approx(r + 0.5 * 4.0 - v)
    # actor 0 ended at t=1: no bootstrap from t=2 into t=1 (A_1 = r_1 − V_1)
    assert buf.advantages[1, 0].item() == pytest.approx(buf.rewards[1, 0].item() - buf.values[1, 0].item())
    assert torch.allclose(buf.returns, buf.advantages + buf.values)
    buf.compute_returns([0, 0, 0, 0], 0.5, 1.0)  # a list of ints is taken as float32
    assert buf.advantages[2, 3].item() == pytest.approx(r - v)


@pytest.mark.parametrize(
    "field, half",
    [
        ("answer_target", "policy"),
        ("logprob", "policy"),
        ("episode_start", "policy"),
        ("action", "policy"),
        ("reward", "outcome"),
    ],
)
def test_a_wrong_shape_names_the_field_it_came_in(field, half):
    buf = RolloutBuffer(T, B, SHAPES)
    p, o = _policy(0, 0), _outcome(0, 0)
    if half == "policy":
        p[field] = torch.zeros(5, dtype=p[field].dtype)
        with pytest.raises(ValueError, match=re.escape(f"{field}: expected shape (2,), got (5,)")):
            buf.insert_policy(
                0,
                p["obs"],
                p["action"],
                p["answer_target"],
                p["logprob"],
                p["value"],
                p["episode_start"],
                envs=GROUPS[0],
            )
    else:
        with pytest.raises(ValueError, match=re.escape(f"{field}: expected shape (2,), got (5,)")):
            buf.insert_outcome(0, torch.zeros(5), o["done"], envs=GROUPS[0])


def test_the_smallest_rollout_and_a_whole_step_for_some_actors():
    buf = RolloutBuffer(1, 1, {"task": ((), torch.int64)})  # one step of one actor is a rollout
    assert buf.values.shape == (1, 1)
    buf = RolloutBuffer(T, B, SHAPES)
    p, o = _policy(2, 1), _outcome(2, 1)
    buf.insert(
        2,
        p["obs"],
        p["action"],
        p["answer_target"],
        p["logprob"],
        p["value"],
        o["reward"],
        o["done"],
        p["episode_start"],
        envs=GROUPS[1],
    )
    assert buf.values[2].tolist() == [0.0, 0.0, 210.0, 210.25] and buf.rewards[2].tolist() == [0.0, 0.0, 2.5, -3.0]


def test_every_storage_lives_on_the_buffers_device():
    """On the 'meta' device (shapes without data, on any machine): a tensor created without the buffer's device
    would land on the CPU. The GPU path keeps the rollout on the device the same way (docs/throughput.md)."""
    buf = RolloutBuffer(T, B, SHAPES, device="meta")
    tensors = dict(buf.obs) | {
        n: getattr(buf, n)
        for n in (
            "actions",
            "answer_targets",
            "logprobs",
            "values",
            "rewards",
            "dones",
            "episode_starts",
            "advantages",
            "returns",
        )
    }
    assert {k: v.device.type for k, v in tensors.items()} == dict.fromkeys(tensors, "meta")
    buf.set_initial_state({"h": torch.zeros(B, 3)})
    assert buf.initial_state["h"].device.type == "meta"
    buf.compute_returns(torch.zeros(B), 0.99, 0.95)
    assert buf.advantages.device.type == "meta" and buf.returns.device.type == "meta"


def test_the_shape_refusals_name_both_shapes():
    from emml.rl.rollout import compute_gae

    r = torch.zeros(T, B)
    with pytest.raises(ValueError, match=re.escape(f"last_value shape (3,) != ({B},)")):
        compute_gae(r, r, r.bool(), torch.zeros(3), 0.99, 0.95)
    with pytest.raises(ValueError, match=re.escape(f"rewards ({T}, {B}), values ({T}, 2) and dones ({T}, {B}) must")):
        compute_gae(r, torch.zeros(T, 2), r.bool(), torch.zeros(B), 0.99, 0.95)
    buf = RolloutBuffer(T, B, SHAPES)
    with pytest.raises(ValueError, match=re.escape(f"state['h'] leading dim {B + 1} != num_envs {B}")):
        buf.set_initial_state({"h": torch.zeros(B + 1, 7)})


def test_the_float_storage_is_float32_whatever_torchs_default_dtype():
    """A caller that runs under float64 defaults (a notebook's `torch.set_default_dtype`) still gets the rollout's
    float32 storage: the update's losses and the stored log-probs then agree in precision with the paper's run."""
    before = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    try:
        buf = RolloutBuffer(T, B, SHAPES)
    finally:
        torch.set_default_dtype(before)
    for name in ("logprobs", "values", "rewards", "advantages", "returns"):
        assert getattr(buf, name).dtype == torch.float32, name
