"""Other learners are found from /proc (a fake one here) and share the cores with a warning."""

from emml.rl.contention import other_learners, share_cores


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
