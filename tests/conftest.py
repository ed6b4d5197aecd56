"""Shared test helpers: the smoke input size, and checks that no ViZDoom engine or shm file is left behind."""

from __future__ import annotations

import glob
import os

import pytest

# `emml train`/`run` re-exec the process under tcmalloc when it is installed: inside pytest that would replace the
# test runner itself (CliRunner invokes the commands in this process)
os.environ["EMML_MALLOC"] = "glibc-tuned"

SMOKE = {"height": 60, "width": 108}
"""The smoke profile's input size: every code path, cheaply (conv3 grid 2×5)."""


def _ancestors(pid: int) -> set[int]:
    out = set()
    while pid > 1 and pid not in out:
        out.add(pid)
        try:
            with open(f"/proc/{pid}/stat") as f:
                pid = int(f.read().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            break
    return out


def engine_pids() -> set[int]:
    """Every running ViZDoom engine on the machine (tests run one at a time, so all of them are ours), except
    those of an emml learner running beside the tests (a training in the background: its evaluations start
    engines at any time). An orphaned engine (its owner gone) is always counted."""
    from emml.rl.contention import other_learners

    others = set(other_learners())
    pids = set()
    for comm in glob.glob("/proc/[0-9]*/comm"):
        try:
            with open(comm) as f:
                if f.read().strip() == "vizdoom":
                    pid = int(comm.split("/")[2])
                    with open(f"/proc/{pid}/stat") as f:
                        if f.read().rsplit(")", 1)[1].split()[0] != "Z" and not (others & _ancestors(pid)):
                            pids.add(pid)
        except (OSError, ValueError):
            continue
    return pids


def shm_files() -> list[str]:
    """Every engine's shared-memory file, except those of a learner's engines beside the tests (engine_pids)."""
    from emml.rl.contention import other_learners

    others, foreign = set(other_learners()), set()
    for comm in glob.glob("/proc/[0-9]*/comm"):
        try:
            with open(comm) as f:
                if f.read().strip() != "vizdoom":
                    continue
            pid = int(comm.split("/")[2])
            if others & _ancestors(pid):
                with open(f"/proc/{pid}/cmdline", "rb") as f:
                    argv = f.read().decode(errors="replace").split("\0")
                if "+viz_instance_id" in argv[:-1]:
                    foreign.add(argv[argv.index("+viz_instance_id") + 1])
        except (OSError, ValueError):
            continue
    return [p for p in glob.glob("/dev/shm/ViZDoom*") if not any(i in p for i in foreign)]


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


@pytest.fixture
def placeholder_table(tmp_path, monkeypatch):
    """A placeholder table 'table9' (a paper table whose runs are not declared yet: the CLI and reports show the
    paper's numbers only), made from Table 5's paper numbers; returns its name."""
    import shutil

    import emml.registry
    import emml.report.tables

    folder = tmp_path / "reproduce"
    (folder / "paper").mkdir(parents=True)
    (folder / "table9.toml").write_text(
        'title = "A table still to build"\npaper_label = "tab:results_h3d"\nstatus = "placeholder"\n'
        'row_header = "Model"\n'
    )
    shutil.copy(emml.registry.REPRODUCE_DIR / "paper" / "table5.csv", folder / "paper" / "table9.csv")
    real_path, real_numbers = emml.registry.table_path, emml.report.tables.paper_numbers
    monkeypatch.setattr(emml.registry, "table_path", lambda n: folder / f"{n}.toml" if n == "table9" else real_path(n))
    monkeypatch.setattr(
        emml.report.tables,
        "paper_numbers",
        lambda n, directory=None: real_numbers(n, folder / "paper") if n == "table9" else real_numbers(n),
    )
    return "table9"
