"""Issue 54, item 7: `emml import-runs` gives one MLflow run per run dir whatever happens: two imports at once into
one (new) sqlite store, an import killed midway (``kill -9``) and run again."""

import json
import subprocess
import sys
import textwrap

import pytest

from emml.runs import import_runs as importer
from emml.runs import store
from emml.runs.import_runs import IMPORTED_FROM, import_runs, relative
from tests.runs.test_import_runs import write_run

IMPORT = textwrap.dedent(
    """
    import json, sys
    from pathlib import Path
    from emml.runs.import_runs import import_runs
    print(json.dumps({r.run_dir: r.outcome for r in import_runs([Path(sys.argv[1])], uri=sys.argv[2])}))
    """
)
KILLED = textwrap.dedent(
    """
    import os, signal, sys
    from pathlib import Path
    from emml.runs import import_runs as importer
    real, calls = importer.log_points, []
    def dying(*args, **kwargs):  # the second run dir's run is made, then the process is killed before its points
        calls.append(1)
        if len(calls) == 2:
            os.kill(os.getpid(), signal.SIGKILL)
        return real(*args, **kwargs)
    importer.log_points = dying
    importer.import_runs([Path(sys.argv[1])], uri=sys.argv[2])
    """
)


def runs_by_dir(experiment: str, uri: str) -> dict[str, list[dict]]:
    """The store's live runs of ``experiment`` by the run dir they were imported from."""
    out: dict[str, list[dict]] = {}
    for run in store.find_runs(experiment, uri=uri):
        out.setdefault(run["tags"].get(IMPORTED_FROM), []).append(run)
    return out


def test_two_imports_at_once_into_a_new_store_make_one_run_per_run_dir(tmp_path):
    dirs = [relative(write_run(tmp_path, "twice", f"run-s{i}", f"{i + 1:x}" * 32)) for i in range(4)]
    uri = f"sqlite:///{tmp_path / 'store' / 'mlflow.db'}"  # not there yet: both would create its tables
    args = [sys.executable, "-c", IMPORT, str(tmp_path / "runs"), uri]
    procs = [subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [err[-2000:] for _, err in outs]
    outcomes = [json.loads(out.strip().splitlines()[-1]) for out, _ in outs]
    for d in dirs:  # each run dir imported by one of them, found in the store by the other
        assert sorted(o[d] for o in outcomes) == ["imported", "skipped"]
    stored = runs_by_dir("twice", uri)
    assert sorted(stored) == sorted(dirs)
    assert all(len(runs) == 1 and runs[0]["status"] == "FINISHED" for runs in stored.values())


def test_an_import_killed_midway_and_run_again_leaves_one_finished_run_per_run_dir(tmp_path):
    dirs = [relative(write_run(tmp_path, "killed", f"run-s{i}", f"{i + 5:x}" * 32)) for i in range(3)]
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    killed = subprocess.run([sys.executable, "-c", KILLED, str(tmp_path / "runs"), uri], capture_output=True)
    assert killed.returncode == -9, killed.stderr[-2000:]
    left = runs_by_dir("killed", uri)
    assert [left[d][0]["status"] for d in dirs[:2]] == ["FINISHED", "RUNNING"] and dirs[2] not in left
    results = {r.run_dir: r for r in import_runs([tmp_path / "runs"], uri=uri)}
    assert [results[d].outcome for d in dirs] == ["skipped", "imported", "imported"]
    assert "interrupted import" in results[dirs[1]].reason
    stored = runs_by_dir("killed", uri)
    assert sorted(stored) == sorted(dirs)
    assert all(len(runs) == 1 and runs[0]["status"] == "FINISHED" for runs in stored.values())
    assert stored[dirs[1]][0]["run_id"] != left[dirs[1]][0]["run_id"]  # the half-made run went; a whole one came
    again = import_runs([tmp_path / "runs"], uri=uri)
    assert {r.outcome for r in again} == {"skipped"} and runs_by_dir("killed", uri).keys() == stored.keys()


def _enospc():
    import errno

    return OSError(errno.ENOSPC, "No space left on device")


def _sqlite_io_error():
    """sqlite's own 'disk I/O error' (a journal it could not write), as SQLAlchemy wraps it and MLflow re-raises."""
    import sqlite3

    from mlflow.exceptions import MlflowException
    from sqlalchemy.exc import OperationalError

    try:
        raise OperationalError("INSERT INTO metrics", {}, sqlite3.OperationalError("disk I/O error"))
    except OperationalError as e:
        return MlflowException(f"(sqlite3.OperationalError) disk I/O error: {e}")


@pytest.mark.parametrize(
    ("fault", "why", "then"),
    [
        (_enospc, "no space left on", "free some space and rerun the same command"),
        (_sqlite_io_error, "a disk I/O error on", "check the disk (its space, its health) and rerun the same command"),
    ],
)
def test_a_full_disk_during_an_import_is_one_line_naming_the_store_folder(tmp_path, monkeypatch, fault, why, then):
    """Issue 65: a full disk during `emml import-runs` printed ~220 lines (two tracebacks, SQLAlchemy's dump of the
    bound rows) and named no folder. Now one line names the store's folder and what was left as it was, the run
    being imported is removed, and the rerun imports the rest once. Issue 85: sqlite's own 'disk I/O error' (its
    journal unwritable: a full disk under it, a failing device) was still a traceback; it is the same one line."""
    from typer.testing import CliRunner

    from emml.cli import app

    dirs = [relative(write_run(tmp_path, "full", f"run-s{i}", f"{i + 9:x}" * 32)) for i in range(3)]
    uri = f"sqlite:///{tmp_path / 'store' / 'mlflow.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    real, calls = importer.log_points, []

    def full(*args, **kwargs):  # the second run dir's run is made, then its points meet a full disk
        calls.append(1)
        if len(calls) == 2:
            raise fault()
        return real(*args, **kwargs)

    monkeypatch.setattr(importer, "log_points", full)
    out = CliRunner().invoke(app, ["import-runs", str(tmp_path / "runs")])
    assert out.exit_code == 2, out.output
    (line,) = [x for x in out.output.splitlines() if x.startswith("error:")]
    assert line == (
        f"error: {why} {tmp_path / 'store'} (the MLflow store; importing {dirs[1]}, its half-made run "
        f"removed, the 1 run dirs before it imported whole): {then}"
    )
    assert "Traceback" not in out.output and sorted(runs_by_dir("full", uri)) == dirs[:1]
    monkeypatch.setattr(importer, "log_points", real)
    again = CliRunner().invoke(app, ["import-runs", str(tmp_path / "runs")])
    assert again.exit_code == 0, again.output
    stored = runs_by_dir("full", uri)
    assert sorted(stored) == dirs and all(len(r) == 1 and r[0]["status"] == "FINISHED" for r in stored.values())


STOPPED = textwrap.dedent(
    """
    import os, signal, sys, time
    from emml.runs import import_runs as importer
    real, calls = importer.log_points, []
    def slow(*args, **kwargs):  # the second run dir's run is made, then its import waits for the stop
        calls.append(1)
        if len(calls) == 2:
            print("importing", flush=True)
            time.sleep(120)
        return real(*args, **kwargs)
    importer.log_points = slow
    from emml.cli import app
    app(["import-runs", sys.argv[1]])
    """
)


def test_sigterm_ends_an_import_as_ctrl_c_does(tmp_path):
    """Issue 65: SIGTERM killed `emml import-runs` at once (exit 143), leaving a RUNNING run in the store until the
    next import. Now, as on Ctrl-C, the run being imported is deleted, one line says what is left, exit 130."""
    import os
    import signal

    dirs = [relative(write_run(tmp_path, "term", f"run-s{i}", f"{i + 2:x}" * 32)) for i in range(3)]
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    proc = subprocess.Popen(
        [sys.executable, "-c", STOPPED, str(tmp_path / "runs")],
        env={**os.environ, "MLFLOW_TRACKING_URI": uri},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        for line in proc.stdout:  # the first run dir's line, then the second's import waiting
            if line.strip() == "importing":
                break
        os.kill(proc.pid, signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err[-2000:]
    assert out.splitlines()[-1].startswith("stopped by signal SIGTERM: 1 run dirs imported, the one being imported")
    left = runs_by_dir("term", uri)
    assert sorted(left) == dirs[:1] and left[dirs[0]][0]["status"] == "FINISHED"  # no RUNNING half-made run
    assert "Traceback" not in err, err[-2000:]
