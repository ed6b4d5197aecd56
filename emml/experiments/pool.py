"""Training runs in processes: each run in a fresh forkserver process, at most `jobs` at a time, tied to its launcher
by a lifeline (a run ends, saving its finished updates, when its launcher does, however it ends); the outcome of each
run, done, failed, stopped or trained by another process, recorded in a `LaunchReport`. The local launcher
(emml/experiments/launch.py) and a Slurm job's pack of runs (emml/experiments/slurm.py) both train through it."""

from __future__ import annotations

import multiprocessing
import os
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field

from emml.experiments.plan import PlannedRun


@dataclass
class LaunchReport:
    """What `run_table` did."""

    table: str
    profile: str
    backend: str
    total: int = 0
    """Runs the table declares under the profile."""
    skipped: list[str] = field(default_factory=list)
    """Already finished (recorded in the results CSV): not launched."""
    done: list[str] = field(default_factory=list)
    """Trained (or resumed, or re-recorded) to the end in this launch."""
    failed: dict[str, str] = field(default_factory=dict)
    """Run name → error (the others went on)."""
    submitted: list[str] = field(default_factory=list)
    """Slurm job ids (backend slurm)."""
    parent_run_id: str | None = None
    placeholder: bool = False
    """The table is a placeholder: nothing to run."""
    stopped: str | None = None
    """Why the launch stopped early (Ctrl-C, SIGTERM): no queued run started, the runs in progress ended KILLED;
    None when it ran to the end."""
    unfinished: list[str] = field(default_factory=list)
    """After a stop: the runs it left unfinished, stopped or never started (the next launch trains them)."""
    busy: dict[str, str] = field(default_factory=dict)
    """Run name → who trains it: held by another live process (its run lock), so not trained here, nor failed."""


STOP_GRACE_S = 8.0
"""Seconds the pool's workers get to end their runs (checkpoint, MLflow run KILLED, engines) after a stop, before
they are killed; a second Ctrl-C kills them at once."""


def train_one(run: PlannedRun, parent_run_id: str | None, train_fn: Callable | None, store: str | None = None) -> str:
    """Worker body (a pool process, a Slurm job or in-process): train one run; returns its run name. ``store``: the
    tracking URI it logs to, when not the launcher's (a Slurm job's own store; set in the run's own process)."""
    from emml.envs.engine import install_signal_handlers

    install_signal_handlers()
    if store is not None:
        os.environ["MLFLOW_TRACKING_URI"] = store
    if train_fn is None:
        from emml.rl.trainer import train as train_fn
    cfg = run.cfg.validate()
    train_fn(cfg, quiet=True, parent_run_id=parent_run_id)
    if run.spec.transfer is not None:  # Table 4: append the detectors and score the test instructions (§5.4)
        from emml.eval.transfer import record_transfer

        record_transfer(cfg, run.spec.transfer.words, run.spec.instructions, run.spec.transfer.detector)
    return run.name


def run_pool(report: LaunchReport, args: list, jobs: int, log, running: dict | None = None) -> None:
    """Train `args`, at most `jobs` at a time, each run in a fresh forkserver process (nothing is queued in a worker
    ahead of time, so a stop starts nothing more). On a stop (KeyboardInterrupt, SystemExit) every running child
    gets SIGTERM (its run ends KILLED, its engines by pid) and those alive after STOP_GRACE_S, or at a second
    Ctrl-C, are killed. ``running``: the dict the live children are kept in (sentinel → (process, args, pipe)), when
    the caller must reach them from elsewhere (a Slurm pack's time-limit handler, emml/experiments/slurm.py)."""
    from multiprocessing.connection import wait

    from emml.envs.engine import private_mp_tempdir

    private_mp_tempdir()
    ctx = multiprocessing.get_context("forkserver")
    queue, running = list(args), ({} if running is None else running)
    # the lifeline: only this process holds its writing end, so every child sees it close however this process
    # ends, `kill -9` included, and ends its run (`_watch_launcher`) instead of training on without a launcher
    lifeline, alive = ctx.Pipe(duplex=False)
    try:
        while queue or running:
            while queue and len(running) < jobs:
                a = queue.pop(0)
                receive, send = ctx.Pipe(duplex=False)
                child = ctx.Process(target=_child, args=(send, a, lifeline), name=f"emml-{a[0].name}")
                child.start()
                send.close()
                running[child.sentinel] = (child, a, receive)
            for sentinel in wait(list(running)):
                child, a, receive = running.pop(sentinel)
                child.join()
                outcome = _received(receive, child)
                collect(report, a[0].name, lambda outcome=outcome: _outcome(*outcome), log)
    except BaseException:
        end_workers([child for child, _, _ in running.values()])
        raise
    finally:
        alive.close()
        lifeline.close()


def _child(send, a, lifeline=None) -> None:
    """A run's process: Ctrl-C is left to the launcher (which stops children by SIGTERM), and so is its life (the
    run ends when the launcher does, `_watch_launcher`); the outcome goes back as ('done', run name), ('stopped',
    why), ('busy', who holds the run) or ('failed', error and traceback)."""
    import signal

    from emml.runs.runlock import RunLocked

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if lifeline is not None:
        _watch_launcher(lifeline)
    try:
        outcome = ("done", train_one(*a))
    except (KeyboardInterrupt, SystemExit) as e:
        outcome = ("stopped", type(e).__name__)
    except RunLocked as e:
        outcome = ("busy", str(e))
    except BaseException as e:  # noqa: BLE001 - reported to the launcher, which goes on with the table
        outcome = ("failed", f"{type(e).__name__}: {e}\n{traceback.format_exc(limit=3)}")
    try:
        send.send(outcome)
    except OSError:  # the launcher is gone (killed): nobody to tell, the run dir says it all
        pass


def _watch_launcher(lifeline) -> None:
    """A daemon thread that waits for the launcher's end (the lifeline's writing end closed: its process ended,
    however), then stops this run as a stop from the launcher would: SIGTERM to itself (the run saves its finished
    updates, ends KILLED in MLflow, its engines and workers end), and SIGKILL after `STOP_GRACE_S` if it has not
    ended by then. Its run lock goes with it, and a rerun of the launch resumes the run."""
    import signal
    import threading
    import time

    def watch() -> None:
        try:
            lifeline.recv()  # nothing is ever sent: returns only by EOF
        except (EOFError, OSError):
            pass
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(STOP_GRACE_S)
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="emml-launcher-watch", daemon=True).start()


def _received(receive, child) -> tuple[str, str]:
    """What a finished child sent, or ('failed', why) when it died without sending (killed, or dead before its
    target ran: the pipe is then at its end, which `poll` also reports as readable)."""
    try:
        if receive.poll():
            return receive.recv()
    except (EOFError, OSError):
        pass
    return ("failed", f"its process died (exit {child.exitcode})")


def _outcome(kind: str, detail: str) -> str:
    from emml.runs.runlock import RunLocked

    if kind == "stopped":
        raise KeyboardInterrupt
    if kind == "busy":
        raise RunLocked(detail)
    if kind == "failed":
        raise RuntimeError(detail)
    return detail


def end_workers(workers: list) -> None:
    """SIGTERM to each live worker, a grace period to end its run, then SIGKILL (a second Ctrl-C: at once)."""
    import signal
    import time

    for w in workers:
        if w.is_alive():
            os.kill(w.pid, signal.SIGTERM)
    try:
        deadline = time.monotonic() + STOP_GRACE_S
        for w in workers:
            w.join(max(0.0, deadline - time.monotonic()))
    except KeyboardInterrupt:
        pass
    for w in workers:
        if w.is_alive():
            w.kill()
            w.join(1.0)


def collect(report: LaunchReport, rname: str, result: Callable[[], str], log) -> None:
    """Record the outcome of run ``rname``; a failure is kept and the launch goes on."""
    from emml.runs.runlock import RunLocked

    try:
        result()
    except RunLocked as e:  # another live process trains it: not this launch's run to train, nor a failure
        report.busy[rname] = str(e)
        log(f"  not trained here: {e}")
        return
    except Exception as e:  # noqa: BLE001 - one failed run must not stop the table
        report.failed[rname] = f"{type(e).__name__}: {e}"
        log(f"  FAILED {rname}: {e}\n{traceback.format_exc(limit=3)}")
        return
    report.done.append(rname)
    log(f"  done {rname} ({len(report.done)}/{report.total - len(report.skipped)})")
