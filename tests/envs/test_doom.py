import os
import signal

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import emml  # noqa: F401  (registers the env ids)
from emml.config.geometry import pixel_cells, receptive_field
from emml.config.schema import DoomConfig
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
        obs, info = env.reset(seed=0)
        assert obs["image"].dtype == np.uint8 and obs["image"].shape == (3, 60, 108)
        assert obs["aux"].dtype == np.uint8 and obs["aux"].shape == (22, 2, 5)
        assert "target" not in obs  # privileged: in info unless asked for
        assert info["target_mask"].dtype == np.uint8 and info["target_mask"].shape == (2, 5)
        assert env.action_space.nvec.tolist() == [4, 22]
    finally:
        env.close()
    env = gym.make("emml/Doom-v0", aux_labels=True, target_in_obs=True, **SMOKE)  # the 'target_mask' control's
    try:
        check_env(env.unwrapped, skip_render_check=True)
        obs, info = env.reset(seed=0)
        assert obs["target"].shape == (2, 5) and np.array_equal(obs["target"], info["target_mask"])
    finally:
        env.close()
    with pytest.raises(ValueError, match="target_in_obs=True needs aux_labels=True"):
        gym.make("emml/Doom-v0", target_in_obs=True, **SMOKE)


@pytest.mark.parametrize("env_id", ["emml/Doom-v0", "emml/House-v0"])
def test_the_spec_limits_episodes_where_the_env_does_and_truncates_once(env_id, no_leftovers):
    """gym.make wraps the env in TimeLimit(spec.max_episode_steps), the env's own max_steps: the episode is
    truncated at that step, by both at once, never earlier (the two counts agree)."""
    from emml.config.env_kinds import GYM_ENVS
    from emml.config.schema import ENV_CONFIGS

    limit = ENV_CONFIGS[env_id]().max_steps
    assert gym.spec(env_id).max_episode_steps == limit and GYM_ENVS[env_id].max_episode_steps == limit
    env = gym.make(env_id, tasks="sgn", **SMOKE)
    try:
        env.reset(seed=0)
        for t in range(1, limit + 1):
            obs, _, terminated, truncated, _ = env.step(np.array([ANSWER, 0]))  # SGN: 'answer' is a no-op step
            assert not terminated and truncated == (t == limit), t
        assert obs["time"] == limit and env.unwrapped.t == limit
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
    assert DoomConfig().wrong_reward == 0.0  # §5.1 names +1 and -0.001 only
    env = make(difficulty="easy", tasks="sgn", shaping=False, wrong_reward=-0.5)
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
    assert term and not info["success"] and r == pytest.approx(-0.5 - 0.001)


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
    assert term and not info2["success"] and r == pytest.approx(-0.001)  # wrong_reward 0 (§5.1)
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
    obs, info = env.reset(seed=4)
    vocab, state = env.vocab, env.state
    gh, gw = obs["aux"].shape[1:]
    assert (gh, gw) == (9, 17)
    rows = np.array(pixel_cells(state.labels_buffer.shape[0], 168, gh))
    cols = np.array(pixel_cells(state.labels_buffer.shape[1], 300, gw))
    expected = np.zeros_like(obs["aux"])
    target = np.zeros((gh, gw), dtype=np.uint8)
    from emml.envs.objects import CLASS_TO_ACTOR

    for label in state.labels:
        name = CLASS_TO_ACTOR[label.object_name]
        ys, xs = np.nonzero(state.labels_buffer == label.value)
        for w in env.dataset.actors[name].words():
            expected[vocab.index(w), rows[ys], cols[xs]] = 1
        if name == env.episode.scene[env.episode.target]:
            target[rows[ys], cols[xs]] = 1
    assert np.array_equal(obs["aux"], expected)
    assert np.array_equal(info["target_mask"], target) and target.sum() > 0
    assert obs["aux"].sum() > 0
    for w in ("smallest", "largest"):
        assert not env.aux_mask[vocab.index(w)]
    for w in ("go", "the", "object", "what"):  # function words: supervised, never on
        assert obs["aux"][vocab.index(w)].sum() == 0
        assert env.aux_mask[vocab.index(w)]
    assert env.aux_mask.sum() == len(vocab) - 2  # all but the two superlatives


def test_scene_grids_give_each_actors_cells_in_scene_order(make):
    """Easy: the five objects stand side by side, all in view: five non-empty grids, the referent's being
    info's 'target_mask'; a word's aux channel is the union of the grids of the actors it describes."""
    env = make(difficulty="easy", aux_labels=True)
    obs, info = env.reset(seed=4)
    grids = env.scene_grids()
    assert grids.shape == (5, *info["target_mask"].shape) and grids.dtype == np.uint8
    assert np.array_equal(grids[env.episode.target], info["target_mask"])
    assert all(g.sum() > 0 for g in grids)
    for w in ("torch", "red", "armor"):
        having = [i for i, name in enumerate(env.episode.scene) if w in env.dataset.actors[name].words()]
        union = grids[having].max(axis=0) if having else np.zeros_like(info["target_mask"])
        assert np.array_equal(obs["aux"][env.vocab.index(w)], union)
    no_labels = make(difficulty="easy")
    no_labels.reset(seed=4)
    with pytest.raises(RuntimeError, match="aux_labels=True"):
        no_labels.scene_grids()


def test_labels_follow_the_conv_grid_not_an_even_partition():
    """conv3 has no padding: at 300 px its 17 cells are centred at 17.5 + 16k, so the last one looks at
    pixels 256..291, not at the last 17th of the frame (282..299)."""
    assert receptive_field() == (36, 16)
    cols = pixel_cells(300, 300, 17)
    assert cols[17] == 0 and cols[26] == 1 and cols[275] == 16 and cols[-1] == 16
    assert [cols.index(k) for k in (1, 16)] == [26, 266]
    assert pixel_cells(320, 300, 17)[-1] == 16  # render pixels are mapped through the resize


@pytest.mark.parametrize("height, width", [(60, 108), (84, 150), (168, 300)])
def test_all_five_easy_objects_are_fully_in_view(make, height, width):
    """The natural 16:9 projection: every Easy object lies wholly inside the frame at the start (with the old
    `+vid_aspect 3` the outer two were cut by the frame's edges)."""
    env = make(difficulty="easy", aux_labels=True, height=height, width=width)
    for seed in range(3):
        env.reset(seed=seed)
        buffer = env.state.labels_buffer
        boxes = sorted((lb.x, lb.x + lb.width) for lb in env.state.labels)
        assert len(boxes) == 5
        assert all(x0 > 0 and x1 < buffer.shape[1] for x0, x1 in boxes), boxes
        for lb in env.state.labels:  # no object pixel in the first or last column
            assert not (buffer[:, [0, -1]] == lb.value).any()


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


def test_invalid_actions_are_refused_by_name(make):
    env = make(tasks="eqa")
    env.reset(seed=0)
    V = len(env.vocab)
    for bad in ([5, 0], [0], [0, 1, 2], [0.5, 1], [3, V], [-1, 0], "go"):
        with pytest.raises(ValueError, match=r"expected two integers \[move, word\], move in 0\.\.3"):
            env.step(bad)
    assert env.t == 0 and not env.ended  # nothing was stepped
    for good in ([0, 0], np.array([1, V - 1]), (2, 3), np.array([0, 0], dtype=np.int32)):
        env.step(good)
    assert env.t == 4


def test_no_step_after_the_episode_ended_or_after_close(make):
    env = make(tasks="eqa")
    env.reset(seed=0)
    _, reward, terminated, _, _ = env.step([ANSWER, (env.answer_id + 1) % len(env.vocab)])  # a wrong answer
    assert terminated
    with pytest.raises(RuntimeError, match=r"after the episode ended .* call reset\(\) first"):
        env.step([ANSWER, env.answer_id])  # once paid +0.999 after the episode had ended
    env.reset(seed=1)
    env.step([FORWARD, 0])  # reset makes it steppable again
    env.close()
    with pytest.raises(RuntimeError, match=r"after close\(\)"):
        env.step([FORWARD, 0])


def test_the_docstrings_have_gymnasiums_sections_and_the_docs_show_the_spaces():
    """The env documented the Gymnasium way: the sections of Gymnasium's env docs, and the docs' table of the spaces
    (docs/environment.md, moved there from the README: issue 63) as the env builds them (no engine starts: one is
    made at the first reset)."""
    from pathlib import Path

    from emml.envs.doom import OBSERVATION_KEYS, space_rows
    from emml.envs.house import HouseEnv

    sections = ("Description", "Action Space", "Observation Space", "Rewards", "Starting State", "Episode End")
    for cls in (DoomEnv, HouseEnv):
        for section in (*sections, "Arguments"):
            assert f"## {section}\n" in cls.__doc__, (cls.__name__, section)
    for key in OBSERVATION_KEYS:
        assert f"`{key}`" in DoomEnv.__doc__
    readme = (Path(__file__).parents[2] / "docs" / "environment.md").read_text()
    env = DoomEnv(aux_labels=True, target_in_obs=True)
    assert set(env.observation_space.spaces) == set(OBSERVATION_KEYS)
    for row in space_rows(env):
        assert row in readme, row
    house = HouseEnv(aux_labels=True)
    assert house.observation_space["time"].n == 421 and house.action_space.nvec.tolist() == [4, 18]
    assert "the House: V = 18, `time` up to 420" in " ".join(readme.split())
