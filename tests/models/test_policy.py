"""Shared model and policy module of Chaplot et al. 2019 (arXiv 1902.01385): shapes,
gradients, ablations, recurrent-state resets and the PACMAN frame window."""

import pytest
import torch

from emml.config.schema import SHARED_MODEL_OPTIONS
from emml.models import (
    MODELS,
    EmmlModel,
    ModelConfig,
    build_model,
    check_architecture,
    model_config,
    model_table,
)
from emml.models.policy import FRAME_LOGITS

V, H, W, MAX_STEPS = 6, 60, 108, 20


def make_obs(t, b, height=H, width=W, vocab=V, seed=0):
    g = torch.Generator().manual_seed(seed)
    tokens = torch.randint(1, vocab + 1, (t, b, 4), generator=g)
    tokens[..., -1] = 0  # right padding
    return {
        "image": torch.randint(0, 256, (t, b, 3, height, width), dtype=torch.uint8, generator=g),
        "tokens": tokens,
        "task": torch.randint(0, 2, (t, b), generator=g),
        "time": torch.randint(0, MAX_STEPS + 1, (t, b), generator=g),
    }


def starts(t, b, first=True):
    es = torch.zeros(t, b, dtype=torch.bool)
    es[0] = first
    return es


def check_shapes(model, out, state, t, b, grid, vocab=V):
    h, w = grid
    assert out.logits.shape == (t, b, 4)
    assert out.value.shape == (t, b)
    assert out.answer_logits.shape == (t, b, vocab)
    assert out.aux_logits.shape == (t, b, vocab, h, w)
    if model.cfg.name == "dual_attention" and model.cfg.spatial_attention:
        assert out.attention.shape == (t, b, h, w)
        torch.testing.assert_close(out.attention.sum((2, 3)), torch.ones(t, b))
    else:
        assert out.attention is None
    assert state["h"].shape == (b, 128)
    for x in (out.logits, out.value, out.answer_logits, out.aux_logits):
        assert torch.isfinite(x).all()


@pytest.mark.parametrize("name", list(MODELS))
@pytest.mark.parametrize("t", [1, 3])
def test_shapes_smoke_size(name, t):
    torch.manual_seed(0)
    model = build_model(name, V, H, W, MAX_STEPS)
    state = model.initial_state(2)
    with torch.no_grad():
        out, new_state = model(make_obs(t, 2), state, starts(t, 2))
    check_shapes(model, out, new_state, t, 2, (2, 5))
    assert set(new_state) == set(state)
    if name == "pacman":
        assert new_state["frames"].shape == (2, 4, 3, H, W)
        assert new_state["frames"].dtype == torch.uint8


@pytest.mark.parametrize("name", list(MODELS))
def test_shapes_paper_size(name):
    torch.manual_seed(0)
    model = build_model(name, 22, 168, 300, MAX_STEPS)
    with torch.no_grad():
        out, state = model(make_obs(1, 2, 168, 300, 22), model.initial_state(2), starts(1, 2))
    check_shapes(model, out, state, 1, 2, (9, 17), vocab=22)


@pytest.mark.parametrize("name", ["dual_attention", "pacman"])
def test_long_rollout_t128(name):
    model = build_model(name, V, 36, 36, 200)
    obs = make_obs(128, 1, 36, 36)
    es = torch.zeros(128, 1, dtype=torch.bool)
    es[[0, 50]] = True
    with torch.no_grad():
        out, _ = model(obs, model.initial_state(1), es)
    assert out.logits.shape == (128, 1, 4)


@pytest.mark.parametrize("name", list(MODELS))
def test_gradients_reach_every_parameter(name):
    torch.manual_seed(0)
    model = build_model(name, V, H, W, MAX_STEPS)
    t, b = 3, 2
    out, _ = model(make_obs(t, b), model.initial_state(b), starts(t, b))
    g = torch.Generator().manual_seed(1)
    loss = sum(
        (torch.randn(x.shape, generator=g) * x).sum()
        for x in (out.logits, out.value, out.answer_logits, out.aux_logits)
    )
    loss.backward()
    for pname, p in model.named_parameters():
        assert p.grad is not None, f"{name}: no gradient for {pname}"
        assert p.grad.abs().sum() > 0, f"{name}: zero gradient for {pname}"


def _policy_in(name):
    return build_model(name, V, H, W, MAX_STEPS).policy.linear.in_features


def test_ablation_parameters():
    full = _policy_in("dual_attention")
    assert full == 2 * 5 + V + 32 + 2  # vec(x_spat) + x_Ans + time + indicator
    assert _policy_in("da_no_indicator") == full - 2
    assert _policy_in("da_no_sa") == V * 2 * 5 + V + 32 + 2
    no_ga2 = build_model("da_no_ga2", V, H, W, MAX_STEPS)
    assert not any(n.startswith("text_encoder.") for n, _ in no_ga2.named_parameters())
    assert not any(
        n.startswith("text_encoder.") for n, _ in build_model("image_only", V, H, W, MAX_STEPS).named_parameters()
    )
    assert list(build_model("dual_attention", V, H, W, MAX_STEPS).fusion.parameters()) == []


def test_no_ga1_attention_ignores_text():
    torch.manual_seed(0)
    model = build_model("da_no_ga1", V, H, W, MAX_STEPS)
    obs = make_obs(1, 2)
    other = dict(obs, tokens=torch.flip(obs["tokens"], dims=[1]))
    with torch.no_grad():
        a, _ = model(obs, model.initial_state(2), starts(1, 2))
        b, _ = model(other, model.initial_state(2), starts(1, 2))
    torch.testing.assert_close(a.attention, b.attention)


def test_no_indicator_ignores_task():
    torch.manual_seed(0)
    model = build_model("da_no_indicator", V, H, W, MAX_STEPS)
    obs = make_obs(1, 2)
    with torch.no_grad():
        a, _ = model(obs, model.initial_state(2), starts(1, 2))
        b, _ = model(dict(obs, task=1 - obs["task"]), model.initial_state(2), starts(1, 2))
    torch.testing.assert_close(a.logits, b.logits)


@pytest.mark.parametrize("name", ["dual_attention", "concat"])
def test_gru_state_resets_at_episode_start(name):
    torch.manual_seed(0)
    model = build_model(name, V, H, W, MAX_STEPS)
    obs = make_obs(4, 2, seed=3)
    es = starts(4, 2)
    es[2, 1] = True  # env 1 starts a new episode at step 2
    with torch.no_grad():
        seq, _ = model(obs, model.initial_state(2), es)
        tail = {k: v[2:] for k, v in obs.items()}
        fresh, _ = model(tail, model.initial_state(2), starts(2, 2))
        # a dirty state is ignored at an episode start
        dirty = {"h": torch.randn(2, 128)}
        reset, _ = model({k: v[:1] for k, v in obs.items()}, dirty, starts(1, 2))
        first, _ = model({k: v[:1] for k, v in obs.items()}, model.initial_state(2), starts(1, 2))
    torch.testing.assert_close(seq.logits[2:, 1], fresh.logits[:, 1])
    torch.testing.assert_close(seq.value[2:, 1], fresh.value[:, 1])
    assert not torch.allclose(seq.value[2:, 0], fresh.value[:, 0])  # env 0 kept its memory
    torch.testing.assert_close(reset.logits, first.logits)
    torch.testing.assert_close(reset.value, first.value)


def _pacman_run_stepwise(model, obs, es, state):
    outs = []
    for t in range(es.shape[0]):
        out, state = model({k: v[t : t + 1] for k, v in obs.items()}, state, es[t : t + 1])
        outs.append(out)
    cat = {f: torch.cat([getattr(o, f) for o in outs]) for f in ("logits", "value", "answer_logits")}
    return cat, state


def test_pacman_stepwise_equals_sequence():
    torch.manual_seed(0)
    model = build_model("pacman", V, 36, 36, MAX_STEPS)
    t, b = 8, 2
    obs = make_obs(t, b, 36, 36, seed=5)
    es = starts(t, b)
    es[5, 1] = True
    with torch.no_grad():
        seq, seq_state = model(obs, model.initial_state(b), es)
        step, step_state = _pacman_run_stepwise(model, obs, es, model.initial_state(b))
    for f in ("logits", "value", "answer_logits"):
        torch.testing.assert_close(getattr(seq, f), step[f], atol=1e-5, rtol=1e-4)
    assert torch.equal(seq_state["frames"], step_state["frames"])
    torch.testing.assert_close(seq_state["h"], step_state["h"], atol=1e-5, rtol=1e-4)


def test_pacman_acting_cache_equals_recomputing_the_window():
    """`acting_state` carries the K-1 frames' conv logits: stepping with it gives the outputs and the raw frames of
    stepping without it (and of the whole sequence at once), runs the conv on one frame per step, and is ignored
    where gradients are on (the PPO replay recomputes the window so that gradients reach every frame's conv)."""
    torch.manual_seed(0)
    model = build_model("pacman", V, 36, 36, MAX_STEPS)
    t, b = 9, 3
    obs = make_obs(t, b, 36, 36, seed=11)
    es = starts(t, b)
    es[4, 0] = es[6, 2] = True
    frames_seen = []
    hook = model.image_encoder.register_forward_hook(lambda m, args, out: frames_seen.append(args[0].shape[0]))
    with torch.no_grad():
        plain, plain_state = _pacman_run_stepwise(model, obs, es, model.initial_state(b))
        acting = model.acting_state(model.initial_state(b))
        frames_seen.clear()
        cached, cached_state = _pacman_run_stepwise(model, obs, es, acting)
        hook.remove()
        seq, _ = model(obs, model.initial_state(b), es)
    assert frames_seen == [b] * t  # the new frame of each env only (without the cache: K frames each)
    for f in ("logits", "value", "answer_logits"):
        torch.testing.assert_close(cached[f], plain[f], atol=1e-5, rtol=1e-4)
        torch.testing.assert_close(cached[f], getattr(seq, f), atol=1e-5, rtol=1e-4)
    assert torch.equal(cached_state["frames"], plain_state["frames"])
    with torch.no_grad():  # the carried logits are those of the carried frames
        want = model.image_encoder(cached_state["frames"].flatten(0, 1)).unflatten(0, (b, 4))
    torch.testing.assert_close(cached_state[FRAME_LOGITS], want, atol=1e-5, rtol=1e-4)
    assert FRAME_LOGITS not in model.replay_state(cached_state)
    # with gradients on, a (stale) cache is not read: the carried frames' conv is recomputed (what lets gradients
    # reach it in the PPO replay)
    stale = dict(cached_state, **{FRAME_LOGITS: torch.zeros_like(cached_state[FRAME_LOGITS])})
    one = {k: v[:1] for k, v in obs.items()}
    no_start = torch.zeros(1, b, dtype=torch.bool)
    out, _ = model(one, stale, no_start)
    with torch.no_grad():
        ref, _ = model(one, model.replay_state(cached_state), no_start)
    torch.testing.assert_close(out.answer_logits, ref.answer_logits, atol=1e-5, rtol=1e-4)


def test_acting_state_is_the_state_without_a_window():
    model = build_model("dual_attention", V, 36, 36, MAX_STEPS)
    state = model.initial_state(2)
    assert model.acting_state(state) is state and model.replay_state(state) == state


def test_pacman_window_contents_and_reset():
    torch.manual_seed(0)
    model = build_model("pacman", V, 36, 36, MAX_STEPS)
    t, b = 7, 1
    obs = make_obs(t, b, 36, 36, seed=7)
    es = starts(t, b)
    with torch.no_grad():
        # episode start pads the window with the first frame
        _, state = model({k: v[:1] for k, v in obs.items()}, model.initial_state(b), es[:1])
        assert torch.equal(state["frames"][0], obs["image"][0, 0].expand(4, 3, 36, 36))
        # after 7 steps the carried frames are the last 4 observed
        _, state = model(obs, model.initial_state(b), es)
        assert torch.equal(state["frames"][0], obs["image"][3:, 0])
        # the window spans 5 frames: frame t-4 matters at step t, frame t-5 does not
        base, _ = model(obs, model.initial_state(b), es)
        for changed_step, matters in ((2, True), (1, False)):
            img = obs["image"].clone()
            img[changed_step] = 255 - img[changed_step]
            alt, _ = model(dict(obs, image=img), model.initial_state(b), es)
            # compare answers at step 6 (answer depends only on the window, not on h)
            same = torch.allclose(alt.answer_logits[6], base.answer_logits[6])
            assert same != matters
        # an episode start discards a dirty window
        dirty = {"h": torch.zeros(b, 128), "frames": torch.randint(0, 256, (b, 4, 3, 36, 36), dtype=torch.uint8)}
        a, _ = model({k: v[:1] for k, v in obs.items()}, dirty, es[:1])
        c, _ = model({k: v[:1] for k, v in obs.items()}, model.initial_state(b), es[:1])
    torch.testing.assert_close(a.answer_logits, c.answer_logits)
    torch.testing.assert_close(a.logits, c.logits)


def test_unknown_model_name_lists_known_names():
    with pytest.raises(ValueError) as err:
        build_model("transformer", V, H, W, MAX_STEPS)
    for name in MODELS:
        assert name in str(err.value)


@pytest.mark.parametrize(
    "kwargs,field",
    [
        ({"name": "bogus"}, "name"),
        ({"hidden": 0}, "hidden"),
        ({"pacman_frames": -1}, "pacman_frames"),
        ({"name": "concat", "ga1": False}, "ga1"),
        ({"task_indicator": "yes"}, "task_indicator"),
        ({"control": "oracle"}, "control"),
        ({"x_image": "tanh"}, "x_image"),
        ({"sentence_readout": "first"}, "sentence_readout"),
        ({"sentence_activation": "tanh"}, "sentence_activation"),
        ({"eq1_words": "nouns"}, "eq1_words"),
        ({"name": "ga", "eq1_words": "content"}, "eq1_words"),
        ({"ga1": False, "eq1_words": "content"}, "eq1_words"),
        ({"answer_grad": "none"}, "answer_grad"),
        ({"name": "ga", "answer_grad": "gate"}, "answer_grad"),
        ({"ga2": False, "answer_grad": "gate"}, "answer_grad"),
        ({"spatial_attention": False, "answer_grad": "centered"}, "answer_grad"),
        ({"state_scale": 1}, "state_scale"),
        ({"state_temperature": 0}, "state_temperature"),
        ({"state_temperature": "sharp"}, "state_temperature"),
        ({"name": "ga", "state_temperature": 0.25}, "state_temperature"),
        ({"spatial_attention": False, "state_temperature": 0.25}, "state_temperature"),
    ],
)
def test_config_validate_names_field(kwargs, field):
    kwargs = dict(kwargs)
    name = kwargs.pop("name", "dual_attention" if field != "pacman_frames" else "pacman")
    with pytest.raises(ValueError, match=field):  # the shared options' values, then the fusion's declared ones
        model_config(name, **kwargs)
    if set(kwargs) <= set(SHARED_MODEL_OPTIONS):  # a ModelConfig built by hand: its values, then the registry's
        with pytest.raises(ValueError, match=field):
            check_architecture(ModelConfig(name=name, **kwargs).validate())


def test_build_model_overrides_and_too_small_image():
    model = build_model("pacman", V, H, W, MAX_STEPS, pacman_frames=3, hidden=64)
    assert model.initial_state(1)["frames"].shape[1] == 2
    assert model.policy.gru.hidden_size == 64
    with pytest.raises(ValueError, match="'hiden' is not an option of model 'concat'; its options: embed_dim, "):
        build_model("concat", V, H, W, MAX_STEPS, hiden=64)
    with pytest.raises(ValueError, match="width"):
        build_model("concat", V, 60, 20, MAX_STEPS)
    assert isinstance(model, EmmlModel)


def test_model_table():
    rows = model_table(V, H, W, MAX_STEPS)
    assert [r["name"] for r in rows] == list(MODELS)
    for r in rows:
        assert isinstance(r["parameters"], int) and r["parameters"] > 0
        assert r["description"] and "{" not in r["description"]
    options = {r["name"]: r["options"] for r in rows}  # each fusion's own, with the entry's values
    assert options["ga"] == {"answer_activation": "relu"} and options["pacman"] == {"pacman_frames": 5}
    assert options["da_no_sa"]["spatial_attention"] is False and options["dual_attention"]["answer_grad"] == "all"


def test_the_description_says_the_x_s_the_code_computes():
    from emml.models import describe

    assert describe("dual_attention").endswith("x_S = h·w·vec(x_spat)")  # state_scale, the default
    assert describe("dual_attention", state_scale=False).endswith("x_S = vec(x_spat)")  # the paper's
    assert describe("dual_attention", state_temperature=0.25).endswith("x_S = h·w·softmax(scores / 0.25)")
    assert describe("da_no_sa").endswith("x_S = vec(x_GA1)")


def _labelled_obs(t=1, b=2, seed=0):
    obs = make_obs(t, b, seed=seed)
    g = torch.Generator().manual_seed(seed + 1)
    obs["aux"] = torch.randint(0, 2, (t, b, V, 2, 5), dtype=torch.uint8, generator=g)
    obs["target"] = torch.zeros(t, b, 2, 5, dtype=torch.uint8)
    obs["target"][..., 1, 3] = 1
    return obs


def test_perfect_detectors_control_reads_the_labels():
    """control='detectors': x_I := aux labels, so the attention is Eq. 2 on the labels, whatever the image."""
    model = build_model("dual_attention", V, H, W, MAX_STEPS, control="detectors")
    obs = _labelled_obs()
    out, _ = model(obs, model.initial_state(2), starts(1, 2))
    bow = model.text_encoder.bag_of_words(obs["tokens"].flatten(0, 1))
    scores = (obs["aux"].flatten(0, 1).float() * bow[:, :, None, None]).sum(1).flatten(1)
    torch.testing.assert_close(out.attention.flatten(0, 1).flatten(1), torch.softmax(scores, 1))
    obs["image"] = 255 - obs["image"]
    out2, _ = model(obs, model.initial_state(2), starts(1, 2))
    torch.testing.assert_close(out2.attention, out.attention)


def test_perfect_state_control_feeds_the_target_cells():
    """control='target_mask': the policy's x_S is the referent's cells (0/1); the rest of the model is unchanged."""
    model = build_model("dual_attention", V, H, W, MAX_STEPS, control="target_mask")
    seen = {}

    def grab(module, args):
        seen["state"] = args[0]

    model.policy.register_forward_pre_hook(grab)
    obs = _labelled_obs()
    model(obs, model.initial_state(2), starts(1, 2))
    torch.testing.assert_close(seen["state"], obs["target"].flatten(2).float())


def test_relu_reading_of_conv3():
    """x_image='relu': the fusion reads relu(conv3) (zero where a detector is off) instead of sigmoid(conv3)."""
    torch.manual_seed(0)
    relu = build_model("dual_attention", V, H, W, MAX_STEPS, x_image="relu", state_scale=False)
    sigm = build_model("dual_attention", V, H, W, MAX_STEPS, state_scale=False)
    sigm.load_state_dict(relu.state_dict())
    obs = make_obs(1, 2)
    a, _ = relu(obs, relu.initial_state(2), starts(1, 2))
    b, _ = sigm(obs, sigm.initial_state(2), starts(1, 2))
    torch.testing.assert_close(a.aux_logits, b.aux_logits)
    bow = relu.text_encoder.bag_of_words(obs["tokens"].flatten(0, 1))
    scores = (torch.relu(a.aux_logits.flatten(0, 1)) * bow[:, :, None, None]).sum(1).flatten(1)
    torch.testing.assert_close(a.attention.flatten(0, 1).flatten(1), torch.softmax(scores, 1))


@pytest.mark.parametrize("name", ["dual_attention", "ga", "pacman"])
def test_text_cache_gives_the_uncached_outputs_bit_for_bit(name):
    """Acting with the instruction cache: the same actions' inputs, step after step, as encoding every step; the
    encoder runs once per distinct token batch; an optimizer step (new weights) empties the cache."""
    torch.manual_seed(0)
    cached = build_model(name, V, H, W, MAX_STEPS)
    plain = build_model(name, V, H, W, MAX_STEPS)
    plain.load_state_dict(cached.state_dict())
    plain.text_cache = None
    groups = [make_obs(1, 2, seed=s) for s in (1, 2)]  # two env groups, each its own instructions
    states = {m: [m.initial_state(2) for _ in groups] for m in (cached, plain)}

    def act(step):
        for g, obs in enumerate(groups):
            obs = {**obs, "time": torch.full((1, 2), step)}
            outs = {}
            with torch.no_grad():
                for m in (cached, plain):
                    outs[m], states[m][g] = m(obs, states[m][g], starts(1, 2, first=step == 0))
            for field in ("logits", "value", "answer_logits"):
                assert torch.equal(getattr(outs[cached], field), getattr(outs[plain], field)), (step, field)

    for step in range(4):
        act(step)
    assert (cached.text_cache.misses, cached.text_cache.hits) == (2, 6)
    optimizer = torch.optim.SGD(list(cached.parameters()) + list(plain.parameters()), lr=0.1)
    out, _ = cached(make_obs(2, 2), cached.initial_state(2), starts(2, 2))
    out2, _ = plain(make_obs(2, 2), plain.initial_state(2), starts(2, 2))
    (out.value.sum() + out.answer_logits.sum() + out2.value.sum() + out2.answer_logits.sum()).backward()
    optimizer.step()  # the same update to both: the cached encodings are stale now
    groups[1]["tokens"][0, 0, 0] = 1 + groups[1]["tokens"][0, 0, 0] % V  # a new instruction in one group
    act(4)
    assert cached.text_cache.misses == 4


def test_read_words_masks_eq1_with_the_datasets_content_words_and_is_a_no_op_elsewhere():
    from emml.tasks.language import Vocabulary, load_dataset

    dataset = load_dataset("doom")
    words = Vocabulary.from_dataset(dataset).words
    model = build_model("dual_attention", len(words), H, W, MAX_STEPS, eq1_words="content")
    model.read_words(words, dataset.content_words())
    kept = {w for w, m in zip(words, model.fusion.eq1_mask.tolist()) if m}
    assert kept == {"red", "green", "blue", "yellow", "torch", "pillar", "keycard", "skullkey", "armor", "short",
                    "tall", "smallest", "largest"}  # fmt: skip
    plain = build_model("dual_attention", len(words), H, W, MAX_STEPS)
    assert plain.read_words(words, dataset.content_words()) is plain and plain.fusion.eq1_mask is None
    with pytest.raises(ValueError, match="3 words for a model of"):
        plain.read_words(words[:3], dataset.content_words())
