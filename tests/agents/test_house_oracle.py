import pytest

from emml.agents.oracle import run_oracle
from emml.envs.house import HouseEnv
from tests.conftest import SMOKE


@pytest.mark.parametrize(
    "task, split, least", [("sgn", "train", 0.98), ("sgn", "test", 0.98), ("eqa", "train", 1.0), ("eqa", "test", 1.0)]
)
def test_house_oracle_plans_through_the_doorways(task, split, least, no_leftovers):
    env = HouseEnv(tasks=task, split=split, **SMOKE)
    try:
        result = run_oracle(env, 20, seed=1000)
    finally:
        env.close()
    assert result["accuracy"] >= least, result["failures"]
    assert result["max_steps"] < 100  # far inside the 420-step limit
