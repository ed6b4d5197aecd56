"""Start and end ViZDoom engines, by pid, whatever way their owner ends.

`DoomGame.init()` forks an engine process and shares memory with it through /dev/shm/ViZDoom*<instance id>
files. If the Python owner dies without `close()`, the engine keeps running and the files stay. So every engine
started here is recorded with its pid and instance id, and `end_engine` closes the game, kills the pid if it
still lives and removes its shm files. An atexit hook ends what is left on normal exit, and
`install_signal_handlers` (emml/envs/stops.py) turns SIGTERM into SystemExit so that `finally` blocks and context
managers run. Each engine runs in a session (and process group) of its own: a terminal's Ctrl-C reaches its owner,
never the engine, which ViZDoom crashes on while it starts (issue 85); the owner ends it by pid.
"""

from __future__ import annotations

import atexit
import contextlib
import glob
import hashlib
import multiprocessing
import multiprocessing.util
import os
import shutil
import signal
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

# how a stop (Ctrl-C, SIGTERM, SIGHUP) is raised and held back lives in emml/envs/stops.py; these names stay here for
# the modules and tests that import them from the engines' module
from emml.envs.stops import install_signal_handlers, stop_after  # noqa: F401

SHM_DIR = "/dev/shm"


class EngineError(RuntimeError):
    """The ViZDoom engine failed to start, died, or stopped answering."""


class WorkerDied(EngineError):
    """An env worker process died (killed, out of memory): its engine is orphaned and its pipe never closes."""


@dataclass
class Engine:
    game: object
    """The vizdoom.DoomGame."""
    pid: int | None
    """The engine process, a child of this process."""
    instance_id: str | None
    """ViZDoom's instance id: names the engine's shm files."""


_LIVE: dict[int, Engine] = {}
_LOCK = threading.Lock()


def _children_named(name: str) -> dict[int, str]:
    """pid → command line of this process's children whose executable is ``name``."""
    me = os.getpid()
    out = {}
    for stat in glob.glob("/proc/[0-9]*/stat"):
        try:
            with open(stat) as f:
                fields = f.read().rsplit(")", 1)[1].split()
            if int(fields[1]) != me:
                continue
            pid = int(stat.split("/")[2])
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                argv = f.read().split(b"\0")
            if os.path.basename(argv[0].decode()) == name:
                out[pid] = " ".join(a.decode() for a in argv)
        except (OSError, IndexError, ValueError):
            continue
    return out


def _instance_id(cmd: str) -> str | None:
    """The engine's instance id (it names its shm files) from its command line, None if absent."""
    argv = cmd.split()
    return argv[argv.index("+viz_instance_id") + 1] if "+viz_instance_id" in argv[:-1] else None


def engine_home() -> Path:
    """Where engines run: ViZDoom writes ``_vizdoom/`` and ``_vizdoom.ini`` into its working directory, which is
    this one (in the temp dir, per user) rather than the user's. ``_vizdoom/`` is made here first: engines that
    start together race on the engine's own check-then-create."""
    home = Path(tempfile.gettempdir()) / f"emml-vizdoom-{os.getuid()}"
    (home / "_vizdoom").mkdir(parents=True, exist_ok=True)
    return home


LAUNCHER = """#!/bin/sh
trap '' INT
cd "{home}" || exit 1
instance=- prev=
for a in "$@"; do [ "$prev" = +viz_instance_id ] && instance=$a; prev=$a; done
read -r stat < /proc/$$/stat
rest=${{stat##*) }}
start=$(echo $rest | cut -d' ' -f20)
record="{records}/$PPID-$$"
mkdir -p "{records}" && echo "$start $instance" > "$record.tmp" && mv "$record.tmp" "$record"
exec {setsid}"{binary}" "$@"
"""
"""The engine's launcher. It records the engine (``<owner pid>-<engine pid>``: start time, /proc/PID/stat field 22,
and instance id, as `_record` writes them) before it ``exec``s the engine, which keeps the pid and the start time:
an owner killed with SIGKILL while ``game.init()`` runs, before `start_engine` could record what it forked, leaves
an engine `sweep_orphans` still finds (one such engine was left on this machine, session 12). ``{setsid}``:
util-linux's ``setsid`` (`setsid_prefix`), which puts the engine in a session and process group of its own and
``exec``s it (no fork: the launcher is no group leader), so that a terminal's Ctrl-C, sent to the owner's process
group, never reaches it. Until then the launcher is in that group: ``trap '' INT`` ignores a Ctrl-C there (and
discards one that came while `start_engine` held it back), which killed the launcher, and the owner's ``init()``
with a segfault (issue 85: Ctrl-C as an evaluation starts its engines)."""


def setsid_prefix() -> str:
    """``"<path of setsid>" `` where util-linux's ``setsid`` is installed, else "" (the engine then shares its owner's
    process group, as before issue 85)."""
    found = shutil.which("setsid")
    return f'"{found}" ' if found else ""


def engine_launcher(binary: str) -> Path:
    """A launcher that starts the engine ``binary`` in :func:`engine_home` (``exec``: the engine keeps the pid
    and name the library and :func:`start_engine` expect), recorded first (`LAUNCHER`). Written once per content,
    atomically."""
    home = engine_home()
    script = LAUNCHER.format(home=home, records=records_dir(), binary=binary, setsid=setsid_prefix())
    path = home / f"vizdoom-{hashlib.sha1(script.encode()).hexdigest()[:12]}.sh"
    if not path.exists():
        fd, tmp = tempfile.mkstemp(dir=home, suffix=".tmp")
        with os.fdopen(fd, "w") as f:
            f.write(script)
        os.chmod(tmp, 0o755)
        os.replace(tmp, path)
    return path


def start_engine(game) -> Engine:
    """``game.init()`` (the engine running in :func:`engine_home`) and record the engine it forked. Raises
    EngineError on failure. A Ctrl-C is held back during ``init()``: the process it forks keeps the mask until the
    launcher's ``trap '' INT`` (`LAUNCHER`), so that no Ctrl-C kills the launcher, which crashed ``init()`` with a
    segfault (issue 85: 5 of 7 `emml train`, 7 of 7 `emml eval`); a stop (Ctrl-C, SIGTERM: `stop_after`) comes once the
    engine is taken live, so that the owner's exit ends it by pid (it was left running, unrecorded, until the next
    `emml` command swept it)."""
    before = set(_children_named("vizdoom"))
    binary = game.get_vizdoom_path()
    if not binary.endswith(".sh"):
        if not binary:  # the library's default: the engine shipped in its package
            import vizdoom

            binary = os.path.join(os.path.dirname(vizdoom.__file__), "vizdoom")
        game.set_vizdoom_path(str(engine_launcher(binary)))
    with stop_after():  # a stop comes once the engine is taken live (else no one ends it: issue 85, `emml eval`)
        try:
            with _ctrl_c_held():  # until init() returns (its fork inherits the mask up to the launcher's trap)
                game.init()
        except Exception as e:  # vizdoom raises its own exception types
            _drop_dead_records()  # what the launcher recorded of an engine that did not start
            raise EngineError(f"ViZDoom failed to start: {e}") from e
        new = {p: c for p, c in _children_named("vizdoom").items() if p not in before}
        pid, instance = None, None
        if len(new) == 1:
            pid, cmd = next(iter(new.items()))
            instance = _instance_id(cmd)
        engine = Engine(game, pid, instance)
        if pid is not None:
            with _LOCK:
                _LIVE[pid] = engine
            _record(engine)
    return engine


@contextlib.contextmanager
def _ctrl_c_held():
    """SIGINT blocked in this thread for the block, delivered after it (SIGTERM is not: an engine that inherited it
    blocked would ignore a SIGTERM for good)."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def records_dir() -> Path:
    """Where every engine started here is recorded on disk (``<owner pid>-<engine pid>``: its start time and
    instance id) until it is ended: what a SIGKILLed owner leaves there, `sweep_orphans` ends."""
    return Path(tempfile.gettempdir()) / f"emml-engines-{os.getuid()}"


def _start_time(pid: int) -> str | None:
    """The process's start time (clock ticks since boot, /proc/PID/stat field 22): with the pid, an identity that a
    reused pid does not share."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return None


def _record(engine: Engine) -> None:
    folder = records_dir()
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{os.getpid()}-{engine.pid}"
    path.write_text(f"{_start_time(engine.pid)} {engine.instance_id or '-'}\n")


def _drop_dead_records() -> None:
    """Remove this process's records of engines that are gone and were never taken live (a failed start)."""
    with _LOCK:
        live = set(_LIVE)
    for path in records_dir().glob(f"{os.getpid()}-*"):
        pid = path.name.partition("-")[2]
        if pid.isdigit() and int(pid) not in live and not _alive(int(pid)):
            with contextlib.suppress(FileNotFoundError):
                path.unlink()


def _unrecord(pid: int) -> None:
    with contextlib.suppress(FileNotFoundError):
        (records_dir() / f"{os.getpid()}-{pid}").unlink()


def sweep_orphans() -> list[int]:
    """End the engines recorded by emml processes that are gone (killed with SIGKILL, whose cleanup never ran):
    each is killed only if its pid still names the very process recorded (same start time), and its shm files are
    removed. Returns the pids ended; a record whose owner lives is left alone."""
    ended = []
    folder = records_dir()
    for path in folder.glob("*-*") if folder.is_dir() else ():
        try:
            owner, pid = (int(x) for x in path.name.split("-"))
            started, instance = path.read_text().split()
        except (OSError, ValueError):
            continue
        if Path(f"/proc/{owner}").exists():
            continue  # its owner lives (and ends it), or a new process took the pid: not provably ours to end
        if _start_time(pid) == started:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
                ended.append(pid)
        if instance != "-":
            for shm in glob.glob(os.path.join(SHM_DIR, f"ViZDoom*{instance}")):
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(shm)
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
    return ended


def _alive(pid: int) -> bool:
    try:
        done, _ = os.waitpid(pid, os.WNOHANG)  # reaps it if it has exited (it is our child)
        return done == 0
    except ChildProcessError:
        return False


def end_engine(engine: Engine) -> None:
    """Close the game, then make sure its process is gone and its shm files removed. Idempotent."""
    with signals_held():
        _end(engine)


@contextlib.contextmanager
def signals_held():
    """Hold SIGINT and SIGTERM back (they are delivered right after): a second signal, such as the parent's
    terminate() after a Ctrl-C that already reached this worker, must not cut a cleanup short."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def _end(engine: Engine, grace: float = 1.0) -> None:
    """Close the game, give its process `grace` seconds to exit, then SIGKILL it; remove its shm files."""
    try:
        if engine.game is not None:
            engine.game.close()
    except Exception:
        pass
    if engine.pid is not None:
        deadline = time.monotonic() + grace
        while _alive(engine.pid) and time.monotonic() < deadline:
            time.sleep(0.01)
        if _alive(engine.pid):
            try:
                os.kill(engine.pid, signal.SIGKILL)
                os.waitpid(engine.pid, 0)
            except (ProcessLookupError, ChildProcessError):
                pass
        with _LOCK:
            _LIVE.pop(engine.pid, None)
    if engine.instance_id:
        for path in glob.glob(os.path.join(SHM_DIR, f"ViZDoom*{engine.instance_id}")):
            try:
                os.unlink(path)
            except FileNotFoundError:
                pass
    if engine.pid is not None:  # the record goes last: while an engine's shm files exist, its record names its owner
        _unrecord(engine.pid)


class RestartBudget:
    """How many deaths in a row a restarting owner tolerates: a death less than ``window`` steps after the last
    restart continues the streak, a later one starts a new streak; a streak longer than ``max_restarts`` raises
    ``error`` (an engine or worker that cannot stay up ends the run with a clear message instead of looping)."""

    def __init__(self, max_restarts: int, window: int, what: str, error: type[EngineError] = EngineError):
        self.max_restarts, self.window, self.what, self.error = max_restarts, window, what, error
        self.restarts = 0
        """Restarts granted so far."""
        self._in_a_row = 0
        self._steps_since = 0

    def step(self) -> None:
        self._steps_since += 1

    def death(self, cause: Exception) -> None:
        """Record a death; raises when the streak is past the budget, else counts a restart."""
        self._in_a_row = self._in_a_row + 1 if self._steps_since < self.window else 1
        self._steps_since = 0
        if self._in_a_row > self.max_restarts:
            raise self.error(
                f"the {self.what} died {self._in_a_row} times in a row, each within {self.window} steps of the last "
                f"restart (max_engine_restarts={self.max_restarts}); last error: {cause}"
            ) from cause
        self.restarts += 1


def become_subreaper() -> bool:
    """Make this process adopt its orphaned descendants (Linux PR_SET_CHILD_SUBREAPER). An env worker that is
    killed leaves its engine running; as our child, `end_orphan_engines` can then end it by pid. False where
    the call is not available."""
    import ctypes

    try:
        return ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0) == 0  # 36 = PR_SET_CHILD_SUBREAPER
    except (OSError, AttributeError):
        return False


def end_orphan_engines() -> list[int]:
    """End (SIGKILL, by pid) every engine that is this process's child but not one it started: engines adopted
    from dead workers (see `become_subreaper`). Their shm files go too. Returns their pids."""
    with _LOCK:
        own = set(_LIVE)
    ended = []
    for pid, cmd in _children_named("vizdoom").items():
        if pid in own:
            continue
        with signals_held():
            _end(Engine(game=None, pid=pid, instance_id=_instance_id(cmd)), grace=0.0)  # nobody is left to close it
        ended.append(pid)
    return ended


def live_engines() -> list[int]:
    """Pids of engines started by this process and not yet ended."""
    with _LOCK:
        return list(_LIVE)


@atexit.register
def _end_all() -> None:
    with _LOCK:
        engines = list(_LIVE.values())
    for engine in engines:
        end_engine(engine)


# Worker processes of multiprocessing leave through os._exit, which skips atexit; multiprocessing's own exit
# finalizers do run there, so the same net is hung on them too (it ends what an interrupted close left).
multiprocessing.util.Finalize(None, _end_all, exitpriority=100)


def private_mp_tempdir() -> Path:
    """Put this process's multiprocessing temp dir (the forkserver's socket) under a folder of its own,
    ``<tmp>/emml-mp-<uid>/<pid>/``, and remove the folders of processes that are gone. multiprocessing removes its
    ``pymp-*`` dir at a normal exit but a SIGKILLed learner leaves it: here, the next start sweeps it away, without
    ever touching another program's ``/tmp/pymp-*``. Call before the first worker process starts."""
    base = Path(tempfile.gettempdir()) / f"emml-mp-{os.getuid()}"
    mine = base / str(os.getpid())
    mine.mkdir(parents=True, exist_ok=True)
    for other in base.iterdir():
        if other.name.isdigit() and other != mine and not Path(f"/proc/{other.name}").exists():
            shutil.rmtree(other, ignore_errors=True)
    if multiprocessing.current_process()._config.get("tempdir") is None:  # not created yet: create it in ours
        saved, tempfile.tempdir = tempfile.tempdir, str(mine)
        try:
            multiprocessing.util.get_temp_dir()
        finally:
            tempfile.tempdir = saved
    return mine
