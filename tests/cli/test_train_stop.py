"""`emml train` stopped (issue 65): SIGTERM or Ctrl-C ends it with the line `emml run` and `emml campaign` end with
(what stopped it, what is left, the command that resumes it) and exit 130 for both (SIGTERM exited 143 with no line).
A real smoke training in a subprocess, stopped by its pid once it has logged an update.

Issue 85: a stop ends within seconds whatever the store is doing (locked by another process at the signal: given up
after `STOP_GRACE_S`, the run marked KILLED at the next start), and a Ctrl-C while an evaluation starts its engines
does not crash the process (the engines, in a process group of their own, never get it)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from emml.runs.records import read_points

ROOT = Path(__file__).resolve().parents[2]
RUN = "dual_attention-easy-noaux-s0-smoke"
LOCKER = (
    "import sqlite3, sys, time\n"
    "c = sqlite3.connect(sys.argv[1], isolation_level=None)\n"
    "c.execute('BEGIN EXCLUSIVE')\n"
    "print('locked', flush=True)\n"
    "time.sleep(600)\n"
)
"""Another process holding the store's sqlite file locked (``BEGIN EXCLUSIVE``: no reader nor writer gets in) until it
is killed."""
ENDS_WITHIN_S = 40
"""How long a stopped training may take to end under a locked store: its in-flight write and its run's end get
`emml.runs.store.STOP_GRACE_S` (3 s) each, the rest is the machine's load (before issue 85: 8 tries × 20 s)."""


def _sigint_as_a_terminal_sends_it():  # a suite started without job control inherits SIGINT ignored: undo it
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _args(tracking, *extra) -> list[str]:
    args = ["train", "--profile", "smoke", "--frames", "1000000", "--run-root", tracking["run_root"]]
    return [*args, "--results-root", tracking["results_root"], *extra]


def _start(args) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "emml", *args],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT), "EMML_MALLOC": "glibc-tuned"},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group: the "terminal" a Ctrl-C comes from
        preexec_fn=_sigint_as_a_terminal_sends_it,
    )


def _wait_for_an_update(proc, tracking) -> None:
    metrics = Path(tracking["run_root"]) / "adhoc" / RUN / "metrics.csv"
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None:
        if metrics.exists() and any(k == "charts/update" for _, k, _ in read_points(metrics)):
            break
        time.sleep(0.2)
    assert proc.poll() is None, proc.communicate()


def _stop(proc, how: str) -> None:
    if how == "ctrl-c":
        os.killpg(proc.pid, signal.SIGINT)  # as a terminal sends it: to the whole foreground process group
    else:
        os.kill(proc.pid, signal.SIGTERM)


def _end(proc) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def _assert_stopped(proc, out, err, args, how) -> None:
    assert proc.returncode == 130, f"rc {proc.returncode}\n{out}\n{err[-3000:]}"
    cause = "Ctrl-C" if how == "ctrl-c" else "signal SIGTERM"
    again = "emml " + " ".join(args)
    assert out.splitlines()[-1] == (
        f"stopped by {cause}: 0 runs finished, 1 not (those in progress ended KILLED, resumable from their "
        f"checkpoints); resume with: {again}"
    ), out
    assert "Traceback" not in err, err[-3000:]


def _run_status(tracking) -> str:
    from emml.runs.checkpoint import load_checkpoint
    from emml.runs.store import client

    run_id = load_checkpoint(Path(tracking["run_root"]) / "adhoc" / RUN / "checkpoint.pt")["run_id"]
    return client(tracking["uri"]).get_run(run_id).info.status


@pytest.mark.parametrize("how", ["sigterm", "ctrl-c"])
def test_a_stopped_train_says_how_to_resume_and_exits_130(tracking, no_leftovers, how):
    args = _args(tracking)
    proc = _start(args)
    try:
        _wait_for_an_update(proc, tracking)
        _stop(proc, how)
        out, err = proc.communicate(timeout=120)
    finally:
        _end(proc)
    _assert_stopped(proc, out, err, args, how)
    assert _run_status(tracking) == "KILLED"


@pytest.mark.parametrize("how", ["sigterm", "ctrl-c"])
def test_a_stop_with_the_store_locked_ends_in_seconds_and_the_next_start_marks_the_run_killed(
    tracking, no_leftovers, how
):
    """The store held locked (BEGIN EXCLUSIVE) by another process from before the signal until the training has
    ended: the training gives its writes up within seconds, prints the resume line, exits 130; its run, left RUNNING
    in the store, is marked KILLED by the next start against that store (a Tracker starting another run)."""
    from emml.runs.tracking import Tracker

    args = _args(tracking)
    proc = _start(args)
    db = tracking["uri"].removeprefix("sqlite:///")
    locker = None
    try:
        _wait_for_an_update(proc, tracking)
        locker = subprocess.Popen([sys.executable, "-c", LOCKER, db], stdout=subprocess.PIPE, text=True)
        assert locker.stdout.readline().strip() == "locked"
        _stop(proc, how)
        stopped_at = time.monotonic()
        out, err = proc.communicate(timeout=120)
        took = time.monotonic() - stopped_at
    finally:
        _end(proc)
        if locker is not None:
            locker.kill()  # by pid: the lock goes with it
            locker.wait()
    _assert_stopped(proc, out, err, args, how)
    assert took < ENDS_WITHIN_S, f"{took:.0f} s to end under a locked store\n{err[-3000:]}"
    assert "marked KILLED at the next start" in err, err[-3000:]
    assert _run_status(tracking) == "RUNNING"  # nothing reached the store after the signal
    Tracker(tracking["uri"]).start("adhoc", "the next start")
    assert _run_status(tracking) == "KILLED"


def test_a_ctrl_c_while_an_evaluation_starts_its_engines_stops_cleanly(tracking, no_leftovers):
    """A Ctrl-C that reaches the process group while an evaluation's engine starts (its launcher has just recorded
    it, emml/envs/engine.py): before issue 85 the engine got it too and crashed, and the owner with it (-11, no
    resume line, the run left RUNNING, an engine orphaned). Evaluations run in the training's own process, so its
    engines are the ones recorded under its pid."""
    from emml.envs.engine import records_dir

    args = _args(tracking, "--set", "eval_every=128")  # an evaluation after the 2nd update (64 frames each)
    proc = _start(args)
    caught = False
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and proc.poll() is None:
            if any(records_dir().glob(f"{proc.pid}-*")):  # an engine of the training's own process is starting
                caught = True
                break
            time.sleep(0.002)
        assert caught and proc.poll() is None, proc.communicate()
        _stop(proc, "ctrl-c")
        out, err = proc.communicate(timeout=120)
    finally:
        _end(proc)
    _assert_stopped(proc, out, err, args, "ctrl-c")
    assert _run_status(tracking) == "KILLED"
    assert not list(records_dir().glob(f"{proc.pid}-*"))  # every engine it started, ended by pid


def test_a_ctrl_c_while_emml_eval_starts_its_engines_leaves_no_engine(tracking, no_leftovers):
    """`emml eval` Ctrl-C'd as its first engine starts (7 of 7 crashed, issue 85): it exits 130 and its engine is
    ended by pid on the way out: the stop comes once the engine is taken live (`start_engine`), where it came right
    after ``init()`` and left the engine unrecorded, running until the next `emml` command swept it (4 of 4 here)."""
    from emml.config.profiles import profile_config
    from emml.envs.engine import records_dir
    from emml.rl.trainer import train

    over = {"run_root": tracking["run_root"], "results_root": tracking["results_root"], "frames": 64}
    over |= {"final_eval_episodes": 1, "diagnose_episodes": 0}
    checkpoint = train(profile_config("smoke", "easy", over), quiet=True).run_dir / "checkpoint.pt"
    proc = _start(["eval", str(checkpoint), "--episodes", "2"])
    caught = False
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and proc.poll() is None:
            if any(records_dir().glob(f"{proc.pid}-*")):  # its first engine is starting
                caught = True
                break
            time.sleep(0.002)
        assert caught and proc.poll() is None, proc.communicate()
        _stop(proc, "ctrl-c")
        out, err = proc.communicate(timeout=120)
    finally:
        _end(proc)
    assert proc.returncode == 130, f"rc {proc.returncode}\n{out}\n{err[-3000:]}"
    assert "Traceback" not in err, err[-3000:]
    assert not list(records_dir().glob(f"{proc.pid}-*"))  # its engine ended by pid (no_leftovers: none alive)
