import os

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


def test_engines_run_in_their_own_dir_not_the_users(tmp_path, monkeypatch, no_leftovers):
    from emml.envs.doom import DoomEnv
    from emml.envs.engine import engine_home

    monkeypatch.chdir(tmp_path)
    env = DoomEnv(height=60, width=108)
    try:
        env.reset(seed=0)
        env.step([0, 0])
        assert os.readlink(f"/proc/{env._engine.pid}/cwd") == str(engine_home())
    finally:
        env.close()
    assert list(tmp_path.iterdir()) == []  # no _vizdoom/, no _vizdoom.ini in the user's directory


def _start_one(directory: str, barrier, out) -> None:
    import tempfile

    from emml.envs.doom import DoomEnv

    tempfile.tempdir = directory  # a fresh temp dir: the map, the launcher and the engine dir are all first made here
    env = DoomEnv(height=60, width=108)
    try:
        barrier.wait()
        env.reset(seed=0)
        env.step([0, 0])
        out.put("ok")
    except Exception as e:  # reported to the parent
        out.put(repr(e))
    finally:
        env.close()


def test_engines_starting_together_in_a_fresh_temp_dir_all_start(tmp_path, monkeypatch, no_leftovers):
    import multiprocessing

    monkeypatch.chdir(tmp_path)
    ctx = multiprocessing.get_context("fork")
    n = 16  # issue 19: a 16-core node starts one engine per core at once
    barrier, out = ctx.Barrier(n), ctx.Queue()
    procs = [ctx.Process(target=_start_one, args=(str(tmp_path / "tmp"), barrier, out)) for _ in range(n)]
    (tmp_path / "tmp").mkdir()
    for p in procs:
        p.start()
    results = [out.get(timeout=120) for _ in procs]
    for p in procs:
        p.join(timeout=60)
    assert results == ["ok"] * n
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tmp"]
