"""Other learners are found from /proc (a fake one here) and share the cores with a warning."""

import os
import subprocess
import sys
from pathlib import Path

from emml.rl.contention import LOWEST_PRIORITY, other_learners, share_cores


def _proc(tmp_path, pid: int, argv: list[str], ppid: int = 1, state: str = "S"):
    d = tmp_path / str(pid)
    d.mkdir()
    (d / "cmdline").write_bytes("\0".join(argv).encode() + b"\0")
    (d / "stat").write_text(f"{pid} (python) {state} {ppid} 0 0")


def test_learners_are_told_from_other_processes(tmp_path):
    _proc(tmp_path, 100, ["/x/.venv/bin/python", "/x/.venv/bin/emml", "train", "--profile", "quick"])
    _proc(tmp_path, 101, ["/x/.venv/bin/python", "/x/.venv/bin/emml", "train"], ppid=100)  # a forked worker
    _proc(tmp_path, 200, ["python3", "-m", "emml.cli", "run", "table2"])
    _proc(tmp_path, 300, ["emml", "list"])  # not a learner
    _proc(tmp_path, 400, ["python", "-m", "pytest", "tests"])
    _proc(tmp_path, 500, ["vizdoom", "+viz_instance_id", "x"])
    assert other_learners(tmp_path) == [100, 200]


def test_a_stopped_learner_is_not_a_competitor(tmp_path):
    """A training paused with SIGSTOP (or Ctrl-Z) uses no CPU: a benchmark beside it keeps every core."""
    _proc(tmp_path, 100, ["/x/.venv/bin/python", "/x/.venv/bin/emml", "run", "table4"], state="T")
    _proc(tmp_path, 200, ["/x/.venv/bin/python", "/x/.venv/bin/emml", "train"], state="R")
    assert other_learners(tmp_path) == [200]


def test_cores_are_shared_and_an_explicit_choice_is_kept():
    assert share_cores(0, cores=2, others=[]) == (0, None)
    threads, warning = share_cores(0, cores=2, others=[123])
    assert threads == 1 and "1 other emml learner(s) running (pid 123)" in warning and "threads=N" in warning
    assert share_cores(0, cores=16, others=[1, 2, 3])[0] == 4
    assert share_cores(2, cores=2, others=[123])[0] == 2


def test_a_campaign_is_a_learner_and_its_status_is_not(tmp_path):
    """A campaign trains in its own process (or a forked child of it): a `train` beside it shares the cores."""
    _proc(tmp_path, 100, ["/x/.venv/bin/python", "-m", "emml.cli", "campaign", "reference", "--no-pin"])
    _proc(tmp_path, 200, ["/x/.venv/bin/emml", "campaign", "reference", "--status"])
    assert other_learners(tmp_path) == [100]


def test_a_command_beside_a_learner_yields_the_cpu_to_it():
    """Beside a learner, a command that trains nothing takes the lowest priority and one thread; with none beside
    it, it keeps both; one that yields already is left as it is. Run in subprocesses (nice only rises); the learners
    are given, /proc's reading is above."""

    def probe(others: list[int], policy: str = "SCHED_OTHER") -> list[str]:
        code = (  # from the default policy (a suite beside a campaign runs at SCHED_IDLE: tests/conftest.py)
            "import os, torch; from emml.rl.contention import defer_to_learners; torch.set_num_threads(2); "
            f"os.sched_setscheduler(0, os.{policy}, os.sched_param(0)); "
            f"m = defer_to_learners({others!r}); print(os.nice(0), torch.get_num_threads(), os.sched_getscheduler(0));"
            " print(m)"
        )
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split(
            "\n"
        )

    first, message = probe([4242])[:2]
    assert first == f"{LOWEST_PRIORITY} 1 {os.SCHED_IDLE}"
    grouped = Path("/proc/sys/kernel/sched_autogroup_enabled").read_text().strip() == "1"
    how = "SCHED_IDLE" + (f", its session's autogroup at nice {LOWEST_PRIORITY}" if grouped else "")
    assert message == (
        f"1 emml learner(s) running (pid 4242): this command runs on CPU time they leave ({how}, one thread)"
        " so as not to slow them."
    )
    assert probe([])[:2] == [f"{os.nice(0)} 2 {os.SCHED_OTHER}", "None"]
    assert probe([4242], "SCHED_IDLE")[:2] == [f"{os.nice(0)} 2 {os.SCHED_IDLE}", "None"]


def test_a_campaigns_status_is_no_learner_in_either_spelling_and_its_run_is():
    from emml.rl.contention import _is_learner

    assert _is_learner(["/x/.venv/bin/emml", "campaign", "run", "reference"])
    assert _is_learner(["python", "-m", "emml.cli", "campaign", "reference", "--no-pin"])  # the deprecated spelling
    assert not _is_learner(["/x/.venv/bin/emml", "campaign", "status", "reference"])
    assert not _is_learner(["/x/.venv/bin/emml", "campaign", "reference", "--status"])
    assert not _is_learner(["/x/.venv/bin/emml", "reports"])


def _autogroup(tmp_path, enabled: str, nice: int):
    (tmp_path / "sys/kernel").mkdir(parents=True)
    (tmp_path / "sys/kernel/sched_autogroup_enabled").write_text(enabled + "\n")
    (tmp_path / "self").mkdir()
    (tmp_path / "self/autogroup").write_text(f"/autogroup-7 nice {nice}\n")
    return tmp_path / "self/autogroup"


def test_under_autogroup_a_yielding_process_lowers_its_sessions_group_and_restores_it(tmp_path, monkeypatch):
    """Under autogroup a SCHED_IDLE process in its own session competes as a whole group (two such busy loops took
    the training from ~200 to 71 frames/s): its session's group goes to nice 19 while it runs, then back; without
    autogroup, or with the group lowered already (a suite's worker), nothing is written or restored."""
    from emml.rl import contention

    exits = []
    monkeypatch.setattr(contention.atexit, "register", lambda fn, *args: exits.append((fn, args)))
    group = _autogroup(tmp_path / "on", "1", 0)
    assert contention._lower_autogroup(tmp_path / "on")
    assert group.read_text() == str(LOWEST_PRIORITY) and len(exits) == 1
    fn, args = exits[0]
    fn(*args)
    assert group.read_text() == "0"

    group = _autogroup(tmp_path / "off", "0", 0)
    assert not contention._lower_autogroup(tmp_path / "off")
    assert group.read_text() == "/autogroup-7 nice 0\n" and len(exits) == 1

    group = _autogroup(tmp_path / "low", "1", LOWEST_PRIORITY)
    assert contention._lower_autogroup(tmp_path / "low")
    assert len(exits) == 1  # lowered by another: not this process's to restore


def test_a_learner_takes_back_its_threads_once_the_other_learner_is_gone(monkeypatch):
    """A learner seen at the run's start shares the cores; at a later evaluation without it, the run takes its own
    threads back (a 3-hour campaign step ran at 1 thread of 2 for a test's training that ended a minute later);
    a thread count the user gave is never changed."""
    import torch

    from emml.rl import contention

    before = torch.get_num_threads()
    others = [[4242]]
    monkeypatch.setattr(contention, "_OWN_THREADS", [2])
    monkeypatch.setattr(contention.os, "cpu_count", lambda: 2)
    monkeypatch.setattr(contention, "other_learners", lambda proc=None: others[0])
    try:
        assert "1 other emml learner(s) running (pid 4242)" in contention.take_cores(0)
        assert torch.get_num_threads() == 1
        assert contention.retake_cores(0) is None  # still beside it
        others[0] = []
        assert contention.retake_cores(0) == "learner threads 1 -> 2 (emml learners beside it: none)"
        assert torch.get_num_threads() == 2
        others[0] = [4242]
        torch.set_num_threads(3)
        assert contention.retake_cores(3) is None and torch.get_num_threads() == 3  # the user's choice
    finally:
        torch.set_num_threads(before)
