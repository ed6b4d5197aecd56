"""Env kinds (emml/config/env_kinds.py): one declaration per kind, and every list derives from it; HouseEnv overrides
the scene, the distance and the reach test of DoomEnv, not its episode loop."""

import gymnasium as gym

import emml  # noqa: F401  (registers the env ids)
from emml.config.env_kinds import ENV_KINDS, GYM_ENVS, env_label, kinds_of
from emml.config.schema import ENV_CONFIGS, ENV_DIFFICULTIES, DoomConfig, HouseConfig, env_config_class
from emml.envs.doom import DoomEnv
from emml.envs.house import HouseEnv
from emml.envs.vector import env_class, make_env
from emml.experiments import fidelity
from emml.experiments.tables import DIFFICULTIES
from emml.report.cells import DIFFICULTY_LABELS
from tests.conftest import SMOKE


def test_each_kind_has_its_config_env_and_registered_id():
    assert tuple(ENV_KINDS) == ENV_DIFFICULTIES == DIFFICULTIES == ("easy", "hard", "house")
    want = {"easy": (DoomConfig, DoomEnv), "hard": (DoomConfig, DoomEnv), "house": (HouseConfig, HouseEnv)}
    for name, kind in ENV_KINDS.items():
        config_cls = env_config_class(name)
        assert (config_cls, env_class(kind.gym_id)) == want[name]
        assert config_cls.GYM_ID == kind.gym_id and name in config_cls.DIFFICULTIES
        assert gym.spec(kind.gym_id).entry_point == GYM_ENVS[kind.gym_id].entry_point
        assert config_cls().max_steps == kind.paper_max_steps  # the defaults are the paper's (§5.1, Appendix C)
    assert set(ENV_CONFIGS) == set(GYM_ENVS)
    assert DoomConfig.DIFFICULTIES == kinds_of(DoomConfig.GYM_ID) == ("easy", "hard")
    assert HouseConfig.DIFFICULTIES == ("house",)
    assert env_config_class("medium") is DoomConfig  # no kind: DoomConfig.validate() names the bad value


def test_derived_tables():
    assert fidelity.PAPER_FRAMES == {"easy": 10_000_000, "hard": 50_000_000, "house": 50_000_000}
    assert fidelity.PAPER_MAX_STEPS == {"easy": 210, "hard": 210, "house": 420}
    assert DIFFICULTY_LABELS == {"easy": "Easy", "hard": "Hard", "house": "House"}
    assert env_label("house") == "House" and env_label("medium") == "medium"


def test_make_env_plays_the_kind(no_leftovers):
    for name, cls in (("hard", DoomEnv), ("house", HouseEnv)):
        env = make_env(env_config_class(name)(difficulty=name, **SMOKE))
        try:
            assert type(env) is cls and env.cfg.difficulty == name
        finally:
            env.close()


def test_house_overrides_hooks_not_the_episode_loop():
    own = set(vars(HouseEnv))
    assert not own & {"reset", "step", "_read_state", "_obs", "_info"}
    assert {"_draw_scene", "_actor", "_target_distance", "_reached", "_scenario"} <= own
    assert DoomEnv.shaped_tasks == ("sgn",) and HouseEnv.shaped_tasks == ("sgn", "eqa")  # §5.1; Appendix C
