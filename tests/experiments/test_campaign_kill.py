"""A campaign owns its runs (issue 54): `kill -9` of a `--jobs 2` campaign leaves no process behind within 10 s (each
run process sees its launcher's lifeline close, saves its finished updates and ends KILLED in MLflow, its engines
and workers with it), and a rerun resumes the runs they held: same MLflow runs, one value per step, finished."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from emml.experiments.campaign import load_campaign, run_campaign
from emml.runs.checkpoint import load_checkpoint
from emml.runs.records import read_points
from emml.runs.rundir import CHECKPOINT, METRICS, RESULTS
from emml.runs.store import find_runs

CAMPAIGN = """
[[steps]]
name = "ga"
table = "table2"
profile = "smoke"
only = {{ model = "ga", difficulty = "easy", aux = [true, false] }}
frames = {frames}
"""
RUNS = ("ga-easy-aux-s0-smoke", "ga-easy-noaux-warm400000-s0-smoke")
LAUNCH = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from emml.experiments.campaign import load_campaign, run_campaign
    run_campaign(load_campaign("kill", Path(sys.argv[1])), sys.argv[2], sys.argv[3], jobs=2, log=print)
    """
)


def _stat(pid: int) -> list[str]:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return []


def _descendants(root: int) -> dict[int, str]:
    """Pid → state of every process under ``root`` (orphans of this session are adopted by it: tests/conftest.py)."""
    parent = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        fields = _stat(int(stat.parent.name))
        if fields:
            parent[int(stat.parent.name)] = (int(fields[1]), fields[0])
    out = {}
    for pid, (_, state) in parent.items():
        p = pid
        while p in parent and p not in (root, 1, 0):
            p = parent[p][0]
        if p == root and pid != root:
            out[pid] = state
    return out


def _updates(run: Path) -> int:
    path = run / METRICS
    return sum(k == "charts/update" for _, k, _ in read_points(path)) if path.exists() else 0


@pytest.mark.slow  # ~2.5 min on 2 busy cores: two smoke runs started, killed, resumed and finished
def test_kill_9_of_a_campaign_leaves_no_process_and_the_rerun_resumes(tracking, tmp_path, no_leftovers):
    folder = tmp_path / "campaigns"
    folder.mkdir()
    (folder / "kill.toml").write_text(CAMPAIGN.format(frames=64_000))
    runs = [Path(tracking["run_root"]) / "table2" / name for name in RUNS]
    before = set(_descendants(os.getpid()))
    proc = subprocess.Popen(
        [sys.executable, "-c", LAUNCH, str(folder), tracking["run_root"], tracking["results_root"]],
        cwd=Path(__file__).resolve().parents[2],
        env={**os.environ, "EMML_MALLOC": "glibc-tuned"},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and min(_updates(r) for r in runs) < 1 and proc.poll() is None:
            time.sleep(0.2)
        assert min(_updates(r) for r in runs) >= 1, "both runs should be training"
        assert len(set(_descendants(os.getpid())) - before) > 3  # the campaign, its forkserver, runs, workers
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        t0 = time.monotonic()
        left = {}
        while time.monotonic() - t0 < 10:
            left = {p: s for p, s in _descendants(os.getpid()).items() if p not in before}
            for pid, state in left.items():
                if state == "Z":  # an adopted orphan that ended: ours to reap
                    try:
                        os.waitpid(pid, os.WNOHANG)
                    except ChildProcessError:
                        pass
            if all(s == "Z" for s in left.values()):
                break
            time.sleep(0.1)
        alive = {p: Path(f"/proc/{p}/cmdline").read_bytes()[:80] for p, s in left.items() if s != "Z"}
        assert not alive, f"processes left {time.monotonic() - t0:.1f} s after kill -9 of the campaign: {alive}"
    finally:
        if proc.poll() is None:
            proc.kill()
    killed = {r.name: load_checkpoint(r / CHECKPOINT) for r in runs}
    for name, ckpt in killed.items():  # each run saved its last whole update and ended KILLED, not RUNNING
        (stored,) = [r for r in find_runs("table2") if r["run_id"] == ckpt["run_id"]]
        assert stored["status"] == "KILLED" and not ckpt["finished"], (name, stored["status"])
    target = max(c["frames"] for c in killed.values()) + 128
    (folder / "kill.toml").write_text(CAMPAIGN.format(frames=target))
    (report,) = run_campaign(load_campaign("kill", folder), tracking["run_root"], tracking["results_root"], jobs=2,
                             log=lambda m: None)  # fmt: skip
    assert sorted(report.done) == sorted(RUNS) and not report.failed and not report.busy
    for run in runs:
        done = load_checkpoint(run / CHECKPOINT)
        assert done["finished"] and done["frames"] == target and done["run_id"] == killed[run.name]["run_id"]
        assert (run / RESULTS).exists()
        points = read_points(run / METRICS)
        assert len({(k, st) for st, k, _ in points}) == len(points)  # one value per step
        assert [st for st, k, _ in points if k == "charts/update"] == list(range(64, target + 1, 64))
