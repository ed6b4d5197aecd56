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


OWNER = """
import sys, time
from emml.envs.doom import DoomEnv
env = DoomEnv(height=60, width=108)
env.reset(seed=0)
print(env._engine.pid, env._engine.instance_id, flush=True)
time.sleep(60)
"""


def test_engines_of_a_sigkilled_owner_are_swept_by_pid_and_start_time(no_leftovers):
    import glob
    import signal
    import subprocess
    import sys

    from emml.envs.engine import records_dir, sweep_orphans

    owner = subprocess.Popen([sys.executable, "-c", OWNER], stdout=subprocess.PIPE, text=True)
    pid, instance = owner.stdout.readline().split()
    record = records_dir() / f"{owner.pid}-{pid}"
    assert record.exists() and int(pid) not in sweep_orphans()  # its owner lives: left alone
    os.kill(owner.pid, signal.SIGKILL)  # no cleanup runs: the engine is orphaned, its shm files stay
    owner.wait()
    assert os.path.exists(f"/proc/{pid}") and glob.glob(f"/dev/shm/ViZDoom*{instance}")
    assert sweep_orphans() == [int(pid)]
    import time

    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and os.path.exists(f"/proc/{pid}"):
        time.sleep(0.05)
    assert not glob.glob(f"/dev/shm/ViZDoom*{instance}") and not record.exists()
    assert sweep_orphans() == []  # nothing twice


def test_a_record_whose_pid_now_names_another_process_is_not_killed(tmp_path, monkeypatch):
    import subprocess

    import emml.envs.engine as engine

    monkeypatch.setattr(engine.tempfile, "gettempdir", lambda: str(tmp_path))
    other = subprocess.Popen(["sleep", "30"])
    try:
        engine.records_dir().mkdir(parents=True)
        (engine.records_dir() / f"999999999-{other.pid}").write_text("1 -\n")  # dead owner, a start time not its
        assert engine.sweep_orphans() == [] and other.poll() is None
        assert list(engine.records_dir().iterdir()) == []
    finally:
        other.kill()
        other.wait()


def test_the_launcher_records_the_engine_before_it_runs(monkeypatch, no_leftovers):
    """An owner SIGKILLed inside ``game.init()`` never reaches `_record`: the launcher's own record is what
    `sweep_orphans` then finds (session 12 left such an engine behind)."""
    import emml.envs.engine as engine
    from emml.envs.doom import DoomEnv

    monkeypatch.setattr(engine, "_record", lambda e: None)  # as if the owner died before recording
    env = DoomEnv(height=60, width=108)
    try:
        env.reset(seed=0)
        pid, instance = env._engine.pid, env._engine.instance_id
        record = engine.records_dir() / f"{os.getpid()}-{pid}"
        assert record.read_text().split() == [engine._start_time(pid), instance]
    finally:
        env.close()
    assert not record.exists()  # ended: unrecorded as before


def test_a_sigterm_inside_stop_after_stops_when_the_block_ends():
    """The trainer's PPO update runs in `stop_after`: a SIGTERM there lets it finish (so a stopped run keeps it),
    then stops as `install_signal_handlers` does; outside a block it stops at once."""
    import signal

    from emml.envs.engine import install_signal_handlers, stop_after

    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGHUP)}
    install_signal_handlers()
    try:
        finished = []
        with pytest.raises(SystemExit) as stop:
            with stop_after():
                with stop_after():  # nested: the outermost block decides
                    os.kill(os.getpid(), signal.SIGTERM)
                    finished.append("inner")
                finished.append("outer")
        assert finished == ["inner", "outer"] and stop.value.code == 128 + signal.SIGTERM
        with stop_after():
            finished.append("no signal")  # a block with no signal ends as usual
        with pytest.raises(SystemExit):
            os.kill(os.getpid(), signal.SIGTERM)
            finished.append("never")
        assert finished[-1] == "no signal"
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)


def test_an_engine_runs_in_a_process_group_of_its_own_and_ignores_the_terminals_ctrl_c(no_leftovers):
    """Issue 85: the engines shared the terminal's process group, and a Ctrl-C reaching one (or its launcher) as it
    started crashed it and its owner (-11). Now the engine is the leader of a session of its own (util-linux setsid,
    no fork: same pid), a Ctrl-C sent to its owner's group does not reach it, and its owner ends it by pid."""
    from emml.envs.doom import DoomEnv
    from emml.envs.engine import live_engines

    env = DoomEnv(height=60, width=108)
    try:
        env.reset(seed=0)
        pid = env._engine.pid
        assert os.getpgid(pid) == pid == os.getsid(pid) and os.getpgid(pid) != os.getpgid(0)
        assert env._engine.pid == pid and pid in live_engines()  # recorded under the pid setsid kept
        env.step(env.action_space.sample())  # the engine answers (started whole through setsid)
    finally:
        env.close()
    assert not os.path.exists(f"/proc/{pid}")
