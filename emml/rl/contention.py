"""Other learners on this machine: two trainings that each use every core slow each other ~10× (measured on
2 cores: 205 s instead of 18 s each, notes/cpu-training.md), so a learner that finds others shares the cores and
says so."""

from __future__ import annotations

import atexit
import contextlib
import os
from pathlib import Path

LEARNER_COMMANDS = ("train", "run", "campaign", "demo", "bench")
"""`emml` subcommands that run a learner (a process of one of them counts as one; `campaign --status` does not)."""


def _is_learner(argv: list[str]) -> bool:
    """An `emml <command>` (console script or `python -m emml.cli`) whose command runs a learner."""
    for i, arg in enumerate(argv[:-1]):
        if os.path.basename(arg) == "emml" or (arg == "-m" and argv[i + 1] == "emml.cli"):
            rest = argv[i + 1 :] if arg != "-m" else argv[i + 2 :]
            status = "--status" in rest or rest[:2] == ["campaign", "status"]  # a campaign's status trains nothing
            return bool(rest) and rest[0] in LEARNER_COMMANDS and not status
    return False


def other_learners(proc: Path = Path("/proc")) -> list[int]:
    """Pids of emml learners other than this process and its ancestors (a re-exec'd or `run`-spawned parent)."""
    mine = {os.getpid()}
    pid = os.getppid()
    while pid > 1 and pid not in mine:
        mine.add(pid)
        pid = _parent(proc / str(pid))
    found = {}  # pid -> parent pid
    for entry in proc.glob("[0-9]*"):
        pid = int(entry.name)
        if pid in mine:
            continue
        try:
            argv = (entry / "cmdline").read_bytes().decode(errors="replace").split("\0")
            if _is_learner([a for a in argv if a]) and _stat(entry)[0] not in STOPPED:
                found[pid] = _parent(entry)
        except OSError:
            continue
    return sorted(p for p, parent in found.items() if parent not in found)  # a forked worker is its learner's


STOPPED = ("T", "t")
"""/proc states of a process that uses no CPU until continued (SIGSTOP, Ctrl-Z; traced): not a competitor. (Counting
a paused training halved the learner threads of every benchmark taken beside it.)"""


def _stat(entry: Path) -> list[str]:
    """The fields of /proc/PID/stat after the command name: state, ppid, ... (empty where unreadable)."""
    try:
        return (entry / "stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return []


def _parent(entry: Path) -> int:
    try:
        return int(_stat(entry)[1])
    except (ValueError, IndexError):
        return 0


def share_cores(threads: int, cores: int | None = None, others: list[int] | None = None) -> tuple[int, str | None]:
    """(torch threads for this learner, a warning or None). ``threads`` > 0 is the user's choice and is kept."""
    cores = cores or os.cpu_count() or 1
    others = other_learners() if others is None else others
    if not others:
        return threads, None
    share = threads or max(1, cores // (len(others) + 1))
    pids = ", ".join(map(str, others))
    return share, (
        f"{len(others)} other emml learner(s) running (pid {pids}): learners that share {cores} cores slow each "
        f"other ~10x; this one uses {share} thread(s). Run them one after another, or give each "
        f"--set threads=N with N x learners <= {cores}."
    )


_OWN_THREADS: list[int] = []
"""This process's torch threads before any sharing (read once: a campaign trains its runs one after another in one
process, and a run that shared must not hand its share to the next as its own)."""


def take_cores(threads: int, others: list[int] | None = None) -> str | None:
    """Set this learner's torch threads: ``threads`` > 0 as given, else all of this process's own or, beside other
    learners (``others``: read from /proc unless given), its share (`share_cores`). Returns the warning, or None."""
    import torch

    if not _OWN_THREADS:
        _OWN_THREADS.append(torch.get_num_threads())
    share, warning = share_cores(threads, others=others)
    torch.set_num_threads(share or _OWN_THREADS[0])
    return warning


def retake_cores(threads: int) -> str | None:
    """At each evaluation: the share taken again from the learners beside it now, so that one seen for a moment at
    the run's start (a test's short training) does not cost the whole run half its threads (seen: a 3-hour campaign
    step at 1 thread of 2, the other learner gone a minute later). ``threads`` > 0 (the user's) is never changed.
    Returns a line saying the change, or None when there is none."""
    import torch

    if threads or not _OWN_THREADS:
        return None
    before, others = torch.get_num_threads(), other_learners()  # /proc read once, for the share and the line
    take_cores(0, others)
    after = torch.get_num_threads()
    return (
        None
        if after == before
        else f"learner threads {before} -> {after} (emml learners beside it: {others or 'none'})"
    )


LOWEST_PRIORITY = 19
"""The nice value a command that is not a learner takes beside learners (`defer_to_learners`), where the kernel has
no SCHED_IDLE."""


def yield_cpu() -> str:
    """Run this process (and what it starts from now on) only on CPU time no other process wants: Linux's SCHED_IDLE,
    else nice 19; where the kernel groups processes by session (autogroup), this session's group at nice 19 too, until
    this process ends (`_lower_autogroup`). Returns which. (Beside a campaign's training on 2 cores, the test suite at
    nice 19 left it ~210 frames/s of its ~570, at SCHED_IDLE ~340: a low nice still takes its slices at the
    training's many wake-ups.)"""
    os.nice(max(0, LOWEST_PRIORITY - os.nice(0)))
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):  # not Linux, or not permitted
        return f"nice {LOWEST_PRIORITY}"
    return "SCHED_IDLE" + (f", its session's autogroup at nice {LOWEST_PRIORITY}" if _lower_autogroup() else "")


def _lower_autogroup(proc: Path = Path("/proc")) -> bool:
    """Under autogroup a SCHED_IDLE or nice-19 process started in its own session (a terminal, a job runner) competes
    as a whole group, at the group's weight, with the training's session: measured on 2 cores, two SCHED_IDLE busy
    loops in their own session left a quick Easy training 71 frames/s against 174-215 with autogroup off; with their
    session's group at nice 19, 163. So the session's group goes to nice 19 and back to its own value when this
    process ends (only the process that lowered it restores it: the suite's workers find it lowered already).
    Returns whether the group is at nice 19 now."""
    group = proc / "self" / "autogroup"
    try:
        if (proc / "sys/kernel/sched_autogroup_enabled").read_text().strip() != "1":
            return False
        before = int(group.read_text().split("nice")[1])
        if before < LOWEST_PRIORITY:
            group.write_text(str(LOWEST_PRIORITY))
            atexit.register(_restore_autogroup, group, before)
    except (OSError, ValueError, IndexError):  # no autogroup here, or not permitted
        return False
    return True


def _restore_autogroup(group: Path, nice: int) -> None:
    """The session's group back to its own nice (a shell's later commands must not run at 19)."""
    with contextlib.suppress(OSError):
        group.write_text(str(nice))


def _yielded() -> bool:
    """Whether this process runs at SCHED_IDLE already (a test suite beside a campaign: tests/conftest.py)."""
    try:
        return os.sched_getscheduler(0) == os.SCHED_IDLE
    except (AttributeError, OSError):  # not Linux: nothing tells, so not yielded
        return False


def defer_to_learners(others: list[int] | None = None) -> str | None:
    """For a command that runs a model but trains nothing (diagnose, eval, rescore, reports, ...) started beside
    emml learners: CPU time no learner wants (`yield_cpu`, inherited by the engines it starts) and one torch thread,
    so that the trainings keep their speed (docs/throughput.md, "Commands beside a training"). Returns the line to
    tell the user, or None where no learner runs or this process yields already (a test suite beside a campaign)."""
    import torch

    others = other_learners() if others is None else others
    if not others or _yielded():
        return None
    how = yield_cpu()
    torch.set_num_threads(1)
    pids = ", ".join(map(str, others))
    return (
        f"{len(others)} emml learner(s) running (pid {pids}): this command runs on CPU time they leave ({how}, one "
        f"thread) so as not to slow them."
    )
