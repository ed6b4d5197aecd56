import os
import signal

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import emml  # noqa: F401  (registers the env ids)
from emml.envs.doom import ANSWER, EASY_SLOTS, EASY_START, FORWARD, DoomEnv
from emml.envs.engine import EngineError, live_engines
from tests.conftest import SMOKE


@pytest.fixture
def make(no_leftovers):
    envs = []

    def _make(**kw):
        env = DoomEnv(**{**SMOKE, **kw})
        envs.append(env)
        return env

    yield _make
    for env in envs:
        env.close()


def test_registered_id_and_check_env(make, no_leftovers):
    env = gym.make("emml/Doom-v0", difficulty="hard", aux_labels=True, **SMOKE)
    try:
        check_env(env.unwrapped, skip_render_check=True)
        obs, _ = env.reset(seed=0)
        assert obs["image"].dtype == np.uint8 and obs["image"].shape == (3, 60, 108)
        assert obs["aux"].dtype == np.uint8 and obs["aux"].shape == (22, 2, 5)
        assert env.action_space.nvec.tolist() == [4, 22]
    finally:
        env.close()


def test_easy_slots_are_exact(make):
    env = make(difficulty="easy")
    env.objects_info = True
    for seed in range(3):
        env.reset(seed=seed)
        seen = {(o.name, round(o.position_x), round(o.position_y)) for o in env.state.objects if o.name != "DoomPlayer"}
        from emml.envs.objects import ACTORS

        want = {(ACTORS[n].spawn_class, x, y) for n, (x, y) in zip(env.episode.scene, EASY_SLOTS)}
        assert seen == want
        assert env.pose[:2] == EASY_START[:2] and round(env.pose[2]) % 360 == EASY_START[2]


def test_hard_positions_spaced_and_placed(make):
    env = make(difficulty="hard")
    env.objects_info = True
    angles = set()
    for seed in range(8):
        env.reset(seed=seed)
        pts = [env.pose[:2], *env.positions]
        d = [np.hypot(a[0] - b[0], a[1] - b[1]) for i, a in enumerate(pts) for b in pts[i + 1 :]]
        assert min(d) >= 90
        engine = sorted((round(o.position_x), round(o.position_y)) for o in env.state.objects if o.name != "DoomPlayer")
        assert engine == sorted(env.positions)
        angles.add(round(env.pose[2]) % 360)
    assert len(angles) > 1


def test_determinism_under_seed(make):
    a, b = make(difficulty="hard"), make(difficulty="hard")
    rng = np.random.default_rng(0)
    actions = [np.array([rng.integers(3), 0]) for _ in range(15)]
    oa, ia = a.reset(seed=7)
    ob, ib = b.reset(seed=7)
    assert ia == ib and np.array_equal(oa["image"], ob["image"])
    for act in actions:
        ra, rb = a.step(act), b.step(act)
        assert np.array_equal(ra[0]["image"], rb[0]["image"]) and ra[1:4] == rb[1:4]
        if ra[2] or ra[3]:
            break


def test_sgn_rewards_success_and_wrong_object(make):
    env = make(difficulty="easy", tasks="sgn", shaping=False)
    for seed in range(30):
        env.reset(seed=seed)
        if env.episode.target == 2:  # straight ahead: walking forward reaches it
            break
    total, info = 0.0, {}
    for _ in range(40):
        _, r, term, trunc, info = env.step(np.array([FORWARD, 0]))
        total += r
        if term or trunc:
            break
    assert term and info["success"] and r == pytest.approx(1.0 - 0.001)
    for seed in range(30, 80):
        env.reset(seed=seed)
        if env.episode.target != 2:
            break
    for _ in range(40):
        _, r, term, trunc, info = env.step(np.array([FORWARD, 0]))
        if term or trunc:
            break
    assert term and not info["success"] and r == pytest.approx(-0.2 - 0.001)


def test_shaping_rewards_approach(make):
    env = make(difficulty="easy", tasks="sgn", shaping=True)
    env.reset(seed=3)
    _, r, *_ = env.step(np.array([FORWARD, 0]))
    _, r2, *_ = env.step(np.array([FORWARD, 0]))
    assert r2 > -0.001  # moving forward towards any Easy slot shortens the distance


def test_eqa_answer_and_time_limit(make):
    env = make(tasks="eqa", max_steps=5)
    _, info = env.reset(seed=0)
    assert info["answer"] >= 0
    _, r, term, trunc, info2 = env.step(np.array([ANSWER, info["answer"]]))
    assert term and info2["success"] and r == pytest.approx(0.999)
    _, info = env.reset(seed=1)
    wrong = (info["answer"] + 1) % 22
    _, r, term, _, info2 = env.step(np.array([ANSWER, wrong]))
    assert term and not info2["success"] and r == pytest.approx(-0.201)
    env.reset(seed=2)
    for _ in range(5):
        obs, _, term, trunc, _ = env.step(np.array([FORWARD, 0]))  # touching objects does not end EQA
        assert not term
    assert trunc and obs["time"] == 5


def test_sgn_answer_action_is_a_noop_step(make):
    env = make(tasks="sgn")
    env.reset(seed=0)
    pose = env.pose
    _, r, term, trunc, _ = env.step(np.array([ANSWER, 3]))
    assert not term and not trunc and env.pose == pose and env.t == 1


def test_aux_labels_line_up_with_bounding_boxes(make):
    env = make(difficulty="easy", aux_labels=True, height=168, width=300)
    obs, _ = env.reset(seed=4)
    vocab, state = env.vocab, env.state
    rh, rw = state.labels_buffer.shape
    gh, gw = obs["aux"].shape[1:]
    assert (gh, gw) == (9, 17)
    expected = np.zeros_like(obs["aux"])
    from emml.envs.objects import CLASS_TO_ACTOR

    for label in state.labels:
        actor = env.dataset.actors[CLASS_TO_ACTOR[label.object_name]]
        ys, xs = np.nonzero(state.labels_buffer == label.value)
        for w in actor.words():
            expected[vocab.index(w), ys * gh // rh, xs * gw // rw] = 1
    assert np.array_equal(obs["aux"], expected)
    assert obs["aux"].sum() > 0
    for w in ("smallest", "largest", "go", "the", "object"):
        assert obs["aux"][vocab.index(w)].sum() == 0
        assert not env.aux_mask[vocab.index(w)]
    assert env.aux_mask.sum() == 11  # 5 object classes, 4 colours, 2 sizes


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"difficulty": "medium"}, "difficulty"),
        ({"split": "val"}, "split"),
        ({"tasks": "vqa"}, "tasks"),
        ({"height": 20}, "height"),
        ({"width": 30}, "width"),
        ({"instructions": ("go to the moon",)}, "moon"),
        ({"instructions": ("go to the red pillar",)}, "instructions"),
        ({"colour": "red"}, "colour"),
    ],
)
def test_bad_input_names_the_field(kwargs, field, no_leftovers):
    with pytest.raises(ValueError, match=field):
        DoomEnv(**{**SMOKE, **kwargs})


def test_engine_death_raises_clear_error(make):
    env = make()
    env.reset(seed=0)
    pid = env._engine.pid
    os.kill(pid, signal.SIGKILL)
    with pytest.raises(EngineError, match="engine"):
        for _ in range(50):
            env.step(np.array([FORWARD, 0]))
            if env.ended:
                env.reset()
    assert pid not in live_engines()


def test_close_after_exception_leaves_nothing(no_leftovers):
    env = DoomEnv(**SMOKE)
    with pytest.raises(RuntimeError, match="mid-episode"):
        try:
            env.reset(seed=0)
            raise RuntimeError("mid-episode failure")
        finally:
            env.close()
