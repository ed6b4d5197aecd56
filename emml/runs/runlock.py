"""One process per run: an exclusive lock on the run directory for the run's lifetime.

The lock is `flock` on `<run dir>/run.lock`, so the kernel releases it when its holder ends in any way (SIGKILL
included): a lock left by a dead process never blocks. The file holds who took it (pid, host, start time), which
`holder` reads to say who is training a run (`emml campaign --status`) and which a refused start names. The file
descriptor is not inherited across exec (PEP 446), so engines and worker processes never hold the lock.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import threading
import time
from contextlib import contextmanager
from pathlib import Path

LOCK = "run.lock"

_held: dict[Path, list] = {}
"""Run dir → [fd, depth]: the locks this process holds (re-entrant: a packed trainer hands a run to a plain one)."""
_guard = threading.Lock()


class RunLocked(RuntimeError):
    """The run is being trained by another live process (the message names its pid and host)."""


def _describe(info: dict) -> str:
    since = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(info["started"])) if "started" in info else "?"
    return f"pid {info.get('pid', '?')} on host {info.get('host', '?')} (since {since})"


def _read(path: Path) -> dict:
    try:
        return json.loads(path.read_text() or "{}")
    except (OSError, ValueError):
        return {}


def take_lock(path: Path, **info) -> int | None:
    """An exclusive flock on ``path`` (created), the file then holding who took it (pid, host, start time and
    ``info``); returns its descriptor (closing it releases the lock), or None when a live process holds it."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    os.ftruncate(fd, 0)
    os.pwrite(
        fd, json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "started": time.time(), **info}).encode(), 0
    )
    return fd


def lock_holder(path: Path) -> dict | None:
    """Who holds the lock ``path`` (`take_lock`'s info), or None when no live process does."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return _read(path) or {"pid": "?", "host": "?"}
    else:
        return None
    finally:
        os.close(fd)


def describe(info: dict) -> str:
    """'pid N on host H (since …)': a lock holder, as a refusal names it."""
    return _describe(info)


@contextmanager
def waiting_lock(path: Path):
    """An exclusive flock on ``path`` (created, never truncated), waited for and held while the block runs: the one
    way the project takes turns on a file (a campaign's pin, a results CSV's rows, a new MLflow store's tables, a run
    dir's import). The kernel releases it however its holder ends."""
    with open(path, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        yield


@contextmanager
def hold_run(directory: Path):
    """Hold the run's lock while the block runs; RunLocked (before anything is written) if another live process
    holds it. Creates the run directory."""
    directory = Path(directory).resolve()
    with _guard:
        if directory in _held:
            _held[directory][1] += 1
        else:
            directory.mkdir(parents=True, exist_ok=True)
            fd = take_lock(directory / LOCK)
            if fd is None:
                raise RunLocked(
                    f"{directory} is being trained by {_describe(_read(directory / LOCK))}: wait for it to end, or "
                    "stop that process; a second start would train the same run twice"
                )
            _held[directory] = [fd, 1]
    try:
        yield
    finally:
        with _guard:
            entry = _held[directory]
            entry[1] -= 1
            if entry[1] == 0:
                del _held[directory]
                os.close(entry[0])  # releases the flock; the file stays (unlinking it would race a new holder)


def holder(directory: Path) -> dict | None:
    """Who holds the run's lock ({'pid', 'host', 'started'}), or None when no live process does."""
    path = Path(directory) / LOCK
    if Path(directory).resolve() in _held:
        return _read(path)
    return lock_holder(path)
