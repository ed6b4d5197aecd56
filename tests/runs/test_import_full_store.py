"""`emml import-runs` into a store whose disk is full, as sqlite itself says it (issue 85): the store's file may not
grow (``PRAGMA max_page_count`` on every connection), so sqlite answers its own "database or disk is full" through
SQLAlchemy and MLflow (before, only an OSError stood for it in the tests). One line names the store's folder; MLflow's
own log of the error (~40 lines each, 95 before the line on a real full disk) is kept out; the rerun imports the rest
once."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
import textwrap

from emml.runs.import_runs import import_runs, relative
from tests.runs.test_import_faults import runs_by_dir
from tests.runs.test_import_runs import write_run

CAPPED = textwrap.dedent(
    """
    import sys
    from sqlalchemy import event
    from sqlalchemy.engine import Engine

    @event.listens_for(Engine, "connect")
    def cap(dbapi_conn, record):  # the store's file may not grow past its pages: sqlite's own full disk
        dbapi_conn.execute("PRAGMA max_page_count = " + sys.argv[1])

    from emml.cli import app
    app(["import-runs", sys.argv[2]])
    """
)


def test_sqlites_own_full_disk_is_one_line_naming_the_store_folder_without_mlflows_log(tmp_path):
    curve = [(64 * s, "losses/policy", 0.5) for s in range(1, 1000)]  # enough points to need new pages
    dirs = [write_run(tmp_path, "full", f"run-s{i}", f"{i + 9:x}" * 32, curve=curve) for i in range(3)]
    uri = f"sqlite:///{tmp_path / 'store' / 'mlflow.db'}"
    import_runs([dirs[0]], uri=uri, log=None)  # the store made, one run in it
    with sqlite3.connect(tmp_path / "store" / "mlflow.db") as db:
        pages = db.execute("PRAGMA page_count").fetchone()[0]
    env = {**os.environ, "MLFLOW_TRACKING_URI": uri, "EMML_MALLOC": "glibc-tuned"}
    full = subprocess.run(
        [sys.executable, "-c", CAPPED, str(pages + 2), str(tmp_path / "runs")],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    out = (full.stdout + full.stderr).splitlines()
    assert full.returncode == 2, out
    assert out[-1] == (
        f"error: no space left on {tmp_path / 'store'} (the MLflow store; importing {relative(dirs[1])}, its "
        "half-made run removed, the 1 run dirs before it imported whole): free some space and rerun the same command"
    ), out
    assert len(out) == 2 and out[0].startswith("skipped"), out  # the run dir before it, then the line: nothing else
    again = import_runs([tmp_path / "runs"], uri=uri, log=None)
    assert [r.outcome for r in again] == ["skipped", "imported", "imported"]
    stored = runs_by_dir("full", uri)
    assert len(stored) == 3 and all(len(r) == 1 and r[0]["status"] == "FINISHED" for r in stored.values())
