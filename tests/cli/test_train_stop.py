"""`emml train` stopped (issue 65): SIGTERM or Ctrl-C ends it with the line `emml run` and `emml campaign` end with
(what stopped it, what is left, the command that resumes it) and exit 130 for both (SIGTERM exited 143 with no line).
A real smoke training in a subprocess, stopped by its pid once it has logged an update."""

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


def _sigint_as_a_terminal_sends_it():  # a suite started without job control inherits SIGINT ignored: undo it
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("how", ["sigterm", "ctrl-c"])
def test_a_stopped_train_says_how_to_resume_and_exits_130(tracking, no_leftovers, how):
    args = ["train", "--profile", "smoke", "--frames", "1000000", "--run-root", tracking["run_root"]]
    args += ["--results-root", tracking["results_root"]]
    proc = subprocess.Popen(
        [sys.executable, "-m", "emml", *args],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT), "EMML_MALLOC": "glibc-tuned"},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group: the "terminal" a Ctrl-C comes from
        preexec_fn=_sigint_as_a_terminal_sends_it,
    )
    metrics = Path(tracking["run_root"]) / "adhoc" / RUN / "metrics.csv"
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and proc.poll() is None:
            if metrics.exists() and any(k == "charts/update" for _, k, _ in read_points(metrics)):
                break
            time.sleep(0.2)
        assert proc.poll() is None, proc.communicate()
        if how == "ctrl-c":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            os.kill(proc.pid, signal.SIGTERM)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, out + err
    cause = "Ctrl-C" if how == "ctrl-c" else "signal SIGTERM"
    again = "emml " + " ".join(args)
    assert out.splitlines()[-1] == (
        f"stopped by {cause}: 0 runs finished, 1 not (those in progress ended KILLED, resumable from their "
        f"checkpoints); resume with: {again}"
    ), out
    assert "Traceback" not in err, err[-3000:]
