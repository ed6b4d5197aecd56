"""Shared test helpers: the smoke input size, and checks that no ViZDoom engine or shm file is left behind."""

from __future__ import annotations

import glob
import os

import pytest

# `emml train`/`run` re-exec the process under tcmalloc when it is installed: inside pytest that would replace the
# test runner itself (CliRunner invokes the commands in this process)
os.environ["EMML_NO_TCMALLOC"] = "1"

SMOKE = {"height": 60, "width": 108}
"""The smoke profile's input size: every code path, cheaply (conv3 grid 2×5)."""


def engine_pids() -> set[int]:
    """Every running ViZDoom engine on the machine (tests run one at a time, so all of them are ours)."""
    pids = set()
    for comm in glob.glob("/proc/[0-9]*/comm"):
        try:
            with open(comm) as f:
                if f.read().strip() == "vizdoom":
                    pid = int(comm.split("/")[2])
                    with open(f"/proc/{pid}/stat") as f:
                        if f.read().rsplit(")", 1)[1].split()[0] != "Z":
                            pids.add(pid)
        except (OSError, ValueError):
            continue
    return pids


def shm_files() -> list[str]:
    return glob.glob("/dev/shm/ViZDoom*")


@pytest.fixture
def no_leftovers():
    """Asserts after the test that it left no engine process and no /dev/shm/ViZDoom* file."""
    before_pids, before_shm = engine_pids(), set(shm_files())
    yield
    import time

    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and (engine_pids() - before_pids or set(shm_files()) - before_shm):
        time.sleep(0.05)
    assert engine_pids() - before_pids == set(), "ViZDoom engine processes left behind"
    assert set(shm_files()) - before_shm == set(), "ViZDoom shm files left behind"


def pytest_configure(config):
    os.environ.setdefault("MLFLOW_TRACKING_URI", "sqlite:////tmp/emml-tests-mlflow.db")


@pytest.fixture
def tracking(tmp_path, monkeypatch):
    """A private MLflow store and run root for one test."""
    uri = f"sqlite:///{tmp_path}/mlflow.db"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    return {"uri": uri, "run_root": str(tmp_path / "runs"), "results_root": str(tmp_path / "results")}
