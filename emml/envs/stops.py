"""How a command is stopped (Ctrl-C, SIGTERM, SIGHUP): the signal raised as an exception in the main thread, held
back inside a `stop_after` block until the block ends, and remembered (`stop_requested`) so that what runs after it
(the store's last writes, emml/runs/store.py) knows to give up within seconds instead of waiting on a busy store.

Ctrl-C raises KeyboardInterrupt and SIGTERM/SIGHUP raise SystemExit(128 + signum), as before issue 85; what changed
is that Ctrl-C is held back like SIGTERM: it landed inside MLflow's metric insert, the connection was dropped without
a rollback, and the process kept sqlite's write lock while ending its run (issue 85).
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""The signals `install_signal_handlers` turns into a stop."""

_deferring = 0
"""How many `stop_after` blocks the main thread is inside: while > 0, a stop signal waits for the outermost to end."""
_pending: int | None = None
"""The signal that arrived inside a `stop_after` block, raised when it ends."""
_stop_at: float | None = None
"""When (time.monotonic) the first stop signal of this process arrived; None if none has."""


def _stop_exception(signum: int) -> BaseException:
    """Ctrl-C as KeyboardInterrupt (what `emml.experiments.launch.stop_cause` calls 'Ctrl-C'), any other signal as
    SystemExit(128 + signum)."""
    return KeyboardInterrupt() if signum == signal.SIGINT else SystemExit(128 + signum)


def _on_signal(signum, frame):
    global _pending
    note_stop()
    if _deferring:
        if _pending is None:  # the first one says what stopped it
            _pending = signum
        return
    raise _stop_exception(signum)


def note_stop() -> None:
    """Remember that this process is stopping (the first call's time counts): a stop that came as an exception from
    elsewhere (Python's own Ctrl-C handler, a test) than `install_signal_handlers`'s handler."""
    global _stop_at
    if _stop_at is None:
        _stop_at = time.monotonic()


def stop_requested() -> float | None:
    """When (time.monotonic) this process was asked to stop, or None."""
    return _stop_at


def reset_stop() -> None:
    """Forget a stop (tests, and a process that goes on after handling one)."""
    global _stop_at, _pending
    _stop_at, _pending = None, None


@contextlib.contextmanager
def stop_after():
    """A block a stop signal does not cut short: the stop (KeyboardInterrupt for Ctrl-C, SystemExit for SIGTERM and
    SIGHUP) comes when the block ends. The trainer's PPO update and its per-update log to the store run in one, so
    that a stopped run keeps the update whole (emml/rl/trainer.py, `checkpoint_on_stop`) and the store's write is
    never cut in the middle (issue 85)."""
    global _deferring, _pending
    _deferring += 1
    try:
        yield
    finally:
        _deferring -= 1
        if not _deferring and _pending is not None:
            signum, _pending = _pending, None
            raise _stop_exception(signum)


def install_signal_handlers() -> None:
    """Ctrl-C, SIGTERM and SIGHUP stop the main thread by an exception (so cleanup code runs), held back inside
    `stop_after`. A SIGINT the process inherited ignored (a launcher's child, emml/experiments/pool.py, or a shell
    without job control) stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        return
    for sig in STOP_SIGNALS:
        if sig == signal.SIGINT and signal.getsignal(sig) is signal.SIG_IGN:
            continue
        signal.signal(sig, _on_signal)
