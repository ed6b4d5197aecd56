"""`emml/House-v0` (emml/envs/house.py): spaces, placement, rewards with path shaping, labels, cleanup."""

import os

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import emml  # noqa: F401  (registers the env ids)
from emml.agents.house_oracle import HouseOracle
from emml.config.schema import HouseConfig
from emml.envs.furniture import spawn_class
from emml.envs.house import ANSWER, FORWARD, HouseEnv
from emml.envs.house_wad import HOUSE
from emml.envs.navigation import distance_at
from tests.conftest import SMOKE


@pytest.fixture
def make(no_leftovers):
    envs = []

    def _make(**kw):
        env = HouseEnv(**{**SMOKE, **kw})
        envs.append(env)
        return env

    yield _make
    for env in envs:
        env.close()


def test_registered_id_and_check_env(no_leftovers):
    env = gym.make("emml/House-v0", aux_labels=True, **SMOKE)
    try:
        check_env(env.unwrapped, skip_render_check=True)
        obs, info = env.reset(seed=0)
        assert obs["image"].dtype == np.uint8 and obs["image"].shape == (3, 60, 108)
        assert obs["aux"].shape == (18, 2, 5) and info["target_mask"].shape == (2, 5) and "target" not in obs
        assert env.action_space.nvec.tolist() == [4, 18]
        assert env.unwrapped.cfg.max_steps == 420
    finally:
        env.close()
    assert gym.spec("emml/House-v0").entry_point == "emml.envs.house:HouseEnv"


def test_config_names_bad_fields():
    with pytest.raises(ValueError, match="difficulty='easy'.*'house'"):
        HouseConfig(difficulty="easy").validate()
    with pytest.raises(ValueError, match="unknown HouseConfig field"):
        HouseEnv(rooms=3)


def test_furniture_at_its_slots_agent_at_the_spawn_colours_drawn(make):
    env = make()
    env.objects_info = True
    colours = set()
    for seed in range(4):
        env.reset(seed=seed)
        seen = sorted(
            (o.name, round(o.position_x), round(o.position_y)) for o in env.state.objects if o.name != "DoomPlayer"
        )
        actors = [env.dataset.actors[n] for n in env.episode.scene]
        assert seen == sorted((spawn_class(a.object, a.color), s.x, s.y) for a, s in zip(actors, HOUSE.slots))
        assert env.pose[:2] == HOUSE.spawn[:2] and round(env.pose[2]) % 360 == HOUSE.spawn[2]
        colours.add(tuple(a.color for a in actors))
    assert len(colours) == 4


def test_sgn_rewards_shape_by_path_distance_and_end_at_the_target(make):
    env = make(tasks="sgn")
    env.reset(seed=0, options={"sentence": "go to the yellow office_chair"})
    cfg = env.cfg
    d0 = env.target_distance()
    assert d0 == pytest.approx(distance_at(env._grid, env._fields[env.targets[0]], *HOUSE.spawn[:2]))
    _, r, terminated, _, _ = env.step(np.array([FORWARD, 0]))  # towards the study door: closer by path
    d1 = env.target_distance()
    assert d1 < d0 and r == pytest.approx(cfg.step_reward + cfg.shaping_coef * (d0 - d1))
    oracle = HouseOracle(env)
    total = r
    while not terminated:
        _, r, terminated, truncated, info = env.step(oracle.act())
        total += r
        assert not truncated
    assert info["success"] and info["target"].endswith("OfficeChair")
    assert env.gaps()[env.targets[0]] <= cfg.reach_distance
    # the shaping sums to the path distance covered: + 1 for success, - 0.001 per step
    assert total == pytest.approx(1 + cfg.step_reward * env.t + cfg.shaping_coef * (d0 - env.target_distance()))


def test_sgn_ends_at_a_wrong_piece_without_reward(make):
    env = make(tasks="sgn")
    env.reset(seed=1, options={"sentence": "go to the refrigerator"})
    chair = next(i for i, s in enumerate(HOUSE.slots) if s.object == "office_chair")

    class ToTheChair(HouseOracle):
        def _target(self) -> int:
            return chair

    oracle = ToTheChair(env)
    for _ in range(100):
        _, r, terminated, truncated, info = env.step(oracle.act())
        if terminated:
            break
    assert terminated and not info["success"] and np.argmin(env.gaps()) == chair
    assert r < 0.01  # step reward and shaping only


def test_eqa_shapes_too_and_ends_at_any_answer(make):
    env = make(tasks="eqa")
    env.reset(seed=2, options={"sentence": "what color is the fireplace"})
    d0 = env.target_distance()
    _, r, terminated, _, _ = env.step(np.array([FORWARD, 0]))
    assert not terminated and r == pytest.approx(
        env.cfg.step_reward + env.cfg.shaping_coef * (d0 - env.target_distance())
    )
    wrong = next(w for w in ("red", "green", "blue", "yellow") if w != env.episode.answer)
    _, r, terminated, _, info = env.step(np.array([ANSWER, env.vocab.index(wrong)]))
    assert terminated and not info["success"] and r == pytest.approx(env.cfg.step_reward)
    env = make(tasks="eqa", split="test")
    env.reset(seed=3, options={"sentence": "what color is the sofa"})  # two sofas: one colour, the nearer one shapes
    assert len(env.targets) == 2
    assert env.target_distance() == pytest.approx(
        min(distance_at(env._grid, env._fields[i], *env.pose[:2]) for i in env.targets)
    )
    _, r, terminated, _, info = env.step(np.array([ANSWER, env.answer_id]))
    assert terminated and info["success"] and r == pytest.approx(1 + env.cfg.step_reward)


def test_aux_labels_see_the_furniture_in_view(make):
    env = make(aux_labels=True, tasks="sgn")
    obs, info = env.reset(seed=0, options={"sentence": "go to the office_chair"})  # seen through the study door
    chair = env.vocab.index("office_chair")
    assert obs["aux"][chair].any() and info["target_mask"].any()
    assert not obs["aux"][env.vocab.index("bed")].any()  # the bedroom is behind two walls
    colour = env.dataset.actors[env.episode.scene[env.targets[0]]].color
    assert obs["aux"][env.vocab.index(colour)].any()


def test_close_ends_the_engine(make):
    env = make()
    env.reset(seed=0)
    pid = env._engine.pid
    env.close()
    env.close()  # idempotent
    assert pid is not None
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)
    with pytest.raises(RuntimeError, match="closed"):
        env.step(np.array([FORWARD, 0]))


def test_vector_env_builds_house_envs(no_leftovers):
    from emml.envs.vector import make_vector_env

    with make_vector_env(HouseConfig(**SMOKE), 2, asynchronous=False) as venv:
        obs, infos = venv.reset(seed=0)
        assert obs["image"].shape == (2, 3, 60, 108) and obs["tokens"].shape == (2, 10)
        assert all(isinstance(e.unwrapped, HouseEnv) for e in venv.envs)
        venv.step(np.array([[FORWARD, 0], [FORWARD, 0]]))
