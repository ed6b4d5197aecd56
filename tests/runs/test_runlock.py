"""One process per run: a second holder is refused naming the first one's pid and host, a lock left by a dead
process (SIGKILL) does not block, the lock is re-entrant within a process, and `emml train` exits 2 on a locked run
before anything is written."""

import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time

import pytest

from emml.runs.runlock import LOCK, RunLocked, hold_run, holder

HOLD = textwrap.dedent(
    """
    import sys, time
    from emml.runs.runlock import hold_run
    with hold_run(sys.argv[1]):
        print("held", flush=True)
        time.sleep(60)
    """
)


def _holding_process(directory):
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(directory)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_a_second_holder_is_refused_by_pid_and_host_and_a_killed_holder_does_not_block(tmp_path):
    run = tmp_path / "runs" / "t" / "r"
    proc = _holding_process(run)
    try:
        assert holder(run)["pid"] == proc.pid
        with pytest.raises(RunLocked, match=rf"pid {proc.pid} on host {socket.gethostname()}"):
            with hold_run(run):
                pass
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert holder(run) is None  # the kernel released the dead holder's lock; its file stays
    assert json.loads((run / LOCK).read_text())["pid"] == proc.pid
    with hold_run(run):
        assert holder(run)["pid"] == os.getpid()
    assert holder(run) is None


def test_the_lock_is_reentrant_in_one_process_and_released_at_the_outermost_exit(tmp_path):
    run = tmp_path / "r"
    with hold_run(run):
        with hold_run(run):  # a packed trainer hands one of its runs to a plain trainer
            pass
        probe = subprocess.run(
            [
                sys.executable,
                "-c",
                "import sys; from emml.runs.runlock import holder; print(holder(sys.argv[1])['pid'])",
                str(run),
            ],
            capture_output=True,
            text=True,
        )
        assert probe.stdout.strip() == str(os.getpid())
    assert holder(run) is None


def test_train_on_a_locked_run_exits_2_naming_the_holder_and_writes_nothing(tracking, monkeypatch):
    from typer.testing import CliRunner

    from emml.cli import app
    from emml.config.profiles import profile_config
    from emml.runs.rundir import run_dir

    cfg = profile_config("smoke", "easy", model="ga", seed=3, table="locks", run_root=tracking["run_root"])
    proc = _holding_process(run_dir(cfg))
    try:
        start = time.monotonic()
        result = CliRunner().invoke(
            app,
            [
                "train",
                "--model",
                "ga",
                "--profile",
                "smoke",
                "--seed",
                "3",
                "--table",
                "locks",
                "--set",
                f"run_root='{tracking['run_root']}'",
                "--set",
                f"results_root='{tracking['results_root']}'",
            ],
        )
        assert result.exit_code == 2, result.output
        assert f"pid {proc.pid}" in result.output and time.monotonic() - start < 30
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert sorted(p.name for p in run_dir(cfg).iterdir()) == [LOCK]  # no checkpoint, no metrics
