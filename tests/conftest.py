"""Shared test helpers: the smoke input size, and checks that no ViZDoom engine or shm file is left behind."""

from __future__ import annotations

import glob
import os
import sys

import pytest

# `emml train`/`run` re-exec the process under tcmalloc when it is installed: inside pytest that would replace the
# test runner itself (CliRunner invokes the commands in this process)
os.environ["EMML_MALLOC"] = "glibc-tuned"

SMOKE = {"height": 60, "width": 108}
"""The smoke profile's input size: every code path, cheaply (conv3 grid 2×5)."""


def _become_subreaper() -> None:
    """Adopt the orphans of this session's descendants (Linux PR_SET_CHILD_SUBREAPER): an engine whose owner a test
    killed stays ours, so `engine_pids` counts it, while another pytest session's or a background training's
    engines, never ours, are not counted (two sessions may run side by side: pytest-xdist, or a helper's run)."""
    import ctypes

    try:
        ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0)  # 36 = PR_SET_CHILD_SUBREAPER
    except (OSError, AttributeError):
        pass


_become_subreaper()


def _stat(pid: int) -> list[str]:
    """The fields of /proc/PID/stat after the command name: state, ppid, ... (empty where gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return []


def _ancestors(pid: int) -> set[int]:
    out = set()
    while pid > 1 and pid not in out:
        out.add(pid)
        try:
            pid = int(_stat(pid)[1])
        except (ValueError, IndexError):
            break
    return out


def _engines() -> dict[int, bool]:
    """Every live ViZDoom engine on the machine -> whether it is this session's (a descendant of this process,
    orphans included: `_become_subreaper`). This session's dead engines are reaped on the way."""
    me, out = os.getpid(), {}
    for comm in glob.glob("/proc/[0-9]*/comm"):
        try:
            with open(comm) as f:
                if f.read().strip() != "vizdoom":
                    continue
            pid = int(comm.split("/")[2])
        except (OSError, ValueError):
            continue
        stat = _stat(pid)
        if not stat:
            continue
        if stat[0] in ("Z", "X"):
            if stat[1] == str(me):  # an adopted orphan that exited: ours to reap (subprocess and multiprocessing
                try:  # wait on the pids they started, never on an adopted one)
                    os.waitpid(pid, os.WNOHANG)
                except ChildProcessError:
                    pass
            continue
        out[pid] = me in _ancestors(pid)
    return out


def engine_pids() -> set[int]:
    """The running ViZDoom engines this test session started (its descendants' and their orphans): engines of a
    training or another pytest session beside it are not counted."""
    return {pid for pid, ours in _engines().items() if ours}


def shm_files() -> list[str]:
    """Every engine's shared-memory file, except those of live engines that are not this session's (`engine_pids`).
    The files are listed before the engines, so that an engine another session starts in between (its file listed,
    its process not yet) cannot pass for one of ours."""
    files = glob.glob("/dev/shm/ViZDoom*")
    foreign = set()
    for pid, ours in _engines().items():
        if ours:
            continue
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                argv = f.read().decode(errors="replace").split("\0")
        except OSError:
            continue
        if "+viz_instance_id" in argv[:-1]:
            foreign.add(argv[argv.index("+viz_instance_id") + 1])
    foreign |= _foreign_records()
    return [p for p in files if not any(i in p for i in foreign)]


def _foreign_records() -> set[str]:
    """Instance ids of engines another live process (a training, another xdist worker) started and has not ended
    yet (`emml.envs.engine.records_dir`): an engine that crashed or was killed leaves its shm files until its owner
    ends it, and they are that owner's, not this session's leftovers."""
    from emml.envs.engine import records_dir

    me, out = os.getpid(), set()
    for record in records_dir().glob("*-*"):
        try:
            owner = int(record.name.split("-")[0])
            instance = record.read_text().split()[1]
        except (OSError, ValueError, IndexError):
            continue
        if instance != "-" and _stat(owner) and me not in _ancestors(owner):
            out.add(instance)
    return out


@pytest.fixture
def no_leftovers():
    """Asserts after the test that it left no engine process and no /dev/shm/ViZDoom* file."""
    before_pids, before_shm = engine_pids(), set(shm_files())
    yield
    import time

    deadline = time.monotonic() + 5
    while True:  # the last look decides: a foreign engine's file that came and went in between is no leftover
        engines, files = engine_pids() - before_pids, set(shm_files()) - before_shm
        if not (engines or files) or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    assert engines == set(), f"ViZDoom engine processes left behind: {sorted(engines)}"
    assert files == set(), f"ViZDoom shm files left behind: {sorted(files)}"


def pytest_configure(config):
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")  # one store per worker: sqlite takes one writer at a time
    os.environ.setdefault("MLFLOW_TRACKING_URI", f"sqlite:////tmp/emml-tests-mlflow-{worker}.db")
    from emml.rl.contention import other_learners, yield_cpu

    learners = other_learners()
    if learners:  # a training on this machine (a campaign): the suite takes only the CPU time it leaves
        config.stash[YIELDED] = f"beside emml learner(s) {', '.join(map(str, learners))}: tests run at {yield_cpu()}"


YIELDED = pytest.StashKey[str]()
"""What `pytest_configure` did to keep from slowing a training beside the suite (shown in the report header)."""


def pytest_report_header(config):
    return config.stash.get(YIELDED, None)


@pytest.fixture(scope="session", autouse=True)
def mlflow_schema_from_a_template(tmp_path_factory):
    """A new sqlite MLflow store made in this process gets its tables copied (sqlite's backup) from one store that
    MLflow built once per session, instead of replaying MLflow's schema migrations: 1-2.4 s per store on 2 cores
    against ~0.1 s, and some 70 tests make one. Other databases, and stores made in child processes, are built by
    MLflow itself. The store's file still appears only when MLflow opens it."""
    import sqlite3

    import mlflow.store.db.utils as db_utils
    import sqlalchemy

    build = db_utils._initialize_tables
    template = tmp_path_factory.mktemp("mlflow-schema") / "mlflow.db"
    engine = sqlalchemy.create_engine(f"sqlite:///{template}")
    build(engine)
    engine.dispose()

    def from_template(engine):
        if engine.dialect.name != "sqlite":
            return build(engine)
        raw = engine.raw_connection()
        try:
            with sqlite3.connect(template) as source:
                source.backup(raw.driver_connection)
        finally:
            raw.close()

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(db_utils, "_initialize_tables", from_template)
        yield


@pytest.fixture(autouse=True)
def no_global_tracking_uri():
    """A test that sets MLflow's process-wide tracking URI (`mlflow.set_tracking_uri`) fails, and the URI is unset: the
    next tests of its xdist worker would read that store instead of their own `MLFLOW_TRACKING_URI` (tests/report/
    test_demo.py's fixture did, and which rl tests then found no run depended on the order xdist gave them)."""
    yield
    utils = sys.modules.get("mlflow.tracking._tracking_service.utils")
    if utils is not None and utils._tracking_uri is not None:
        utils._tracking_uri = None
        pytest.fail("the test set mlflow.set_tracking_uri: use the `tracking` fixture (MLFLOW_TRACKING_URI) instead")


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

    import emml.experiments.table_files
    import emml.report.cells
    from emml.config.paths import REPRODUCE_DIR

    folder = tmp_path / "reproduce"
    (folder / "paper").mkdir(parents=True)
    (folder / "table9.toml").write_text(
        'title = "A table still to build"\npaper_label = "tab:results_h3d"\nstatus = "placeholder"\n'
        'row_header = "Model"\n'
    )
    for csv in (REPRODUCE_DIR / "paper").glob("*.csv"):  # the paper's numbers as they are, and table9's
        shutil.copy(csv, folder / "paper" / csv.name)
    shutil.copy(REPRODUCE_DIR / "paper" / "table5.csv", folder / "paper" / "table9.csv")
    real_path = emml.experiments.table_files.table_path
    monkeypatch.setattr(
        emml.experiments.table_files, "table_path", lambda n: folder / f"{n}.toml" if n == "table9" else real_path(n)
    )
    monkeypatch.setattr(emml.report.cells, "PAPER_DIR", folder / "paper")
    return "table9"


@pytest.fixture(autouse=True)
def tables_validated_again():
    """Each test validates the tables it loads itself (`emml.experiments.tables.LOADED` caches a process's tables by
    their bytes, not by the profiles or model registry a test may change)."""
    from emml.experiments.tables import LOADED

    LOADED.clear()
    yield
    LOADED.clear()


@pytest.fixture(autouse=True)
def stop_forgotten():
    """A test that stops a training in this process (a SIGTERM it sends itself, an abort after KeyboardInterrupt)
    leaves it noted (emml/envs/stops.py): forgotten after it, or the next tests' store calls would be given up after
    `emml.runs.store.STOP_GRACE_S`."""
    yield
    from emml.envs.stops import reset_stop

    reset_stop()
