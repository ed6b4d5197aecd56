import pytest

from emml.agents.oracle import run_oracle
from emml.envs.doom import DoomEnv
from tests.conftest import SMOKE


@pytest.mark.parametrize(
    "difficulty, task, episodes, least",
    [("easy", "sgn", 40, 0.98), ("hard", "sgn", 60, 0.95), ("easy", "eqa", 20, 1.0), ("hard", "eqa", 20, 1.0)],
)
def test_oracle_solves_episodes(difficulty, task, episodes, least, no_leftovers):
    env = DoomEnv(difficulty=difficulty, tasks=task, **SMOKE)
    try:
        result = run_oracle(env, episodes, seed=1000)
    finally:
        env.close()
    assert result["accuracy"] >= least, result["failures"]
    assert result["max_steps"] < 210
