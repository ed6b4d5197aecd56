import pytest

from emml.envs.engine import EngineError, RestartBudget, WorkerDied


def test_restart_budget_counts_only_deaths_in_a_row():
    budget = RestartBudget(max_restarts=2, window=10, what="engine")
    for _ in range(5):  # deaths far apart never exhaust the budget
        budget.death(RuntimeError("crash"))
        for _ in range(10):
            budget.step()
    assert budget.restarts == 5
    budget.death(RuntimeError("crash"))  # a streak: 1, 2 — then the third is one too many
    budget.death(RuntimeError("crash"))
    with pytest.raises(EngineError, match="engine died 3 times in a row, each within 10 steps"):
        budget.death(RuntimeError("crash"))


def test_restart_budget_raises_the_error_type_it_was_given():
    budget = RestartBudget(max_restarts=0, window=10, what="env worker", error=WorkerDied)
    with pytest.raises(WorkerDied, match="env worker died 1 times"):
        budget.death(RuntimeError("killed"))
