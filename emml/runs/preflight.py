"""Pre-flight: what a run needs from the machine, checked in seconds before any engine, model or MLflow run starts —
the tracking store reachable and writable, the run and results folders writable, the results CSV readable. Without
it, an unreachable store failed after ~100 s of MLflow's connection retries with a traceback that never named it,
and a read-only results folder after the whole training. Each failure is one line naming the URI or the path
(PreflightError, a ValueError: the CLI prints it and exits 2). Nothing is created: probes are removed at once. A new
sqlite store is created by `ensure_store`, once, under a lock, where the first MLflow run is about to be made."""

from __future__ import annotations

import json
import os
import socket
import sqlite3
import tempfile
import urllib.error
import urllib.request
from contextlib import closing
from pathlib import Path
from urllib.parse import urlparse

from emml.config.schema import TrainConfig
from emml.runs.runlock import waiting_lock
from emml.runs.store import client, sqlite_path, tracking_uri

STORE_TIMEOUT_S = 5.0
"""The longest a store check waits (a lock held by another writer, a server that does not answer)."""
SQLITE_HEADER = b"SQLite format 3\x00"
"""The first 16 bytes of every SQLite database file."""
DB_PORTS = {"postgresql": 5432, "mysql": 3306, "mssql": 1433}
"""Default ports of the database servers MLflow can track in (the URI's scheme before any '+driver')."""


class PreflightError(ValueError):
    """A run could not write its results: the message names the store or the path, and why (one line)."""


def check_train(*cfgs: TrainConfig, timeout: float = STORE_TIMEOUT_S) -> None:
    """Everything ``cfgs`` (validated) write to, before the first of them starts (`emml train`, `emml run`): the
    store once, then each run's directory, and each results folder and the results CSV its runs will upsert."""
    from emml.runs.results import read_results
    from emml.runs.rundir import results_csv, run_dir

    check_store(timeout=timeout)
    for cfg in cfgs:
        check_writable(f"run_root={cfg.run_root!r}", run_dir(cfg))
    for csv, cfg in {results_csv(c): c for c in cfgs}.items():  # a table's runs share one CSV: read once
        check_writable(f"results_root={cfg.results_root!r}", csv.parent)
        read_results(csv)  # ResultsError (a ValueError) names the file and the line


def check_writable(what: str, path: str | os.PathLike) -> Path:
    """The folder ``path`` is, or would be created in, takes a new file (a probe, created and deleted); returns
    that folder. ``what`` names the setting in the message, e.g. "run_root='runs'"."""
    folder = Path(path)
    try:
        while not folder.exists():  # the nearest folder that exists: the rest is made by the writer
            folder = folder.parent
    except OSError as e:
        raise PreflightError(f"{what}: cannot look into {folder} ({e.strerror})") from None
    if not folder.is_dir():
        raise PreflightError(f"{what}: {folder} is not a directory")
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".emml-preflight-")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise PreflightError(f"{what}: cannot create files in {folder} ({e.strerror})") from None
    return folder


def check_store(uri: str | None = None, timeout: float = STORE_TIMEOUT_S) -> None:
    """The MLflow tracking store (``uri``, default $MLFLOW_TRACKING_URI or the project's sqlite file) answers
    within ``timeout`` seconds and, where that can be told without a client (sqlite, a file store), takes
    writes. Other schemes (databricks, …) are left to MLflow."""
    uri = uri or tracking_uri()
    where = f"MLflow store {uri}"
    scheme = urlparse(uri).scheme.split("+")[0]
    if uri in ("databricks", "databricks-uc"):  # a profile of the Databricks CLI, not a path
        return
    if scheme == "sqlite":
        db = sqlite_path(uri)
        if db is not None:  # None: in memory
            _check_sqlite(where, db, timeout)
    elif scheme in ("", "file"):
        check_writable(where, urlparse(uri).path if scheme else uri)
    elif scheme in ("http", "https"):
        _check_server(where, uri, timeout)
    elif scheme in DB_PORTS:
        parsed = urlparse(uri)
        _check_socket(where, parsed.hostname or "localhost", parsed.port or DB_PORTS[scheme], timeout)


def _check_sqlite(where: str, db: Path, timeout: float) -> None:
    check_writable(where, db.parent)  # SQLite writes its journal beside the database
    if not db.exists():
        return  # MLflow creates it
    if not db.is_file():
        raise PreflightError(f"{where}: {db} is not a file")
    try:
        with open(db, "r+b") as f:
            head = f.read(len(SQLITE_HEADER))
    except OSError as e:
        raise PreflightError(f"{where}: {db} cannot be opened for writing ({e.strerror})") from None
    if head and head != SQLITE_HEADER:  # an empty file is an empty database
        raise PreflightError(f"{where}: {db} is not an SQLite database")
    con = None
    try:
        con = sqlite3.connect(f"{db.as_uri()}?mode=rw", uri=True, timeout=timeout)
        con.execute("SELECT count(*) FROM sqlite_master").fetchone()
    except sqlite3.OperationalError as e:
        if "locked" not in str(e):  # locked: another writer, which the tracker waits for
            raise PreflightError(f"{where}: {db} cannot be read ({e})") from None
    except sqlite3.DatabaseError as e:
        raise PreflightError(f"{where}: {db} is a damaged SQLite database ({e})") from None
    finally:
        if con is not None:
            con.close()


MLFLOW_PROBE = "/api/2.0/mlflow/experiments/get-by-name?experiment_name=Default"
"""A read of MLflow's REST API that every tracking server answers with JSON: the experiment, or an MLflow error
(`error_code`) when it has none of that name. Any other web server answers it otherwise (issue 54: a server that
was not MLflow passed a check of the port alone, and training failed 12 s later in a ~200-line traceback)."""


def _check_server(where: str, uri: str, timeout: float) -> None:
    """An MLflow tracking server answers its REST API (`MLFLOW_PROBE`); one behind authentication (401, 403) is
    left to MLflow and its credentials. What it does with writes cannot be told without a run."""
    url = f"{uri.rstrip('/')}{MLFLOW_PROBE}"
    try:
        with urllib.request.urlopen(url, timeout=timeout) as answer:
            status, body = answer.status, answer.read(65536)
    except urllib.error.HTTPError as e:
        if e.code in (401, 403):
            return
        status, body = e.code, e.read(65536)
        if e.code >= 500 and not _mlflow_answer(body):
            raise PreflightError(f"{where}: the server answers with an error ({e.code} {e.reason})") from None
    except (urllib.error.URLError, OSError) as e:
        reason = getattr(e, "reason", e)
        raise PreflightError(f"{where}: cannot be reached ({reason}; waited up to {timeout:g} s)") from None
    if not _mlflow_answer(body):
        raise PreflightError(
            f"{where}: answers, but is not an MLflow tracking server (GET {MLFLOW_PROBE.split('?')[0]} gave HTTP "
            f"{status} without MLflow's JSON); point MLFLOW_TRACKING_URI at the URL `mlflow server` serves"
        )


def _mlflow_answer(body: bytes) -> bool:
    """Whether ``body`` is what MLflow's REST API answers: a JSON object with the experiment or an `error_code`."""
    try:
        data = json.loads(body.decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        return False
    return isinstance(data, dict) and ("experiment" in data or "error_code" in data)


def ensure_store(uri: str | None = None) -> None:
    """Create a new sqlite store's tables once, under a lock on its file, before the first MLflow run is made in
    it: MLflow builds them on first use, and two processes doing so at once (two launches started together on a new
    store) fail with `table _alembic_tmp_experiments already exists` (issue 54). A store that has its tables, and any
    store that is not an sqlite file, is left to MLflow."""
    uri = uri or tracking_uri()
    db = sqlite_path(uri) if urlparse(uri).scheme.split("+")[0] == "sqlite" else None
    if db is None or _has_tables(db):
        return
    db.parent.mkdir(parents=True, exist_ok=True)
    with waiting_lock(db):  # a second start waits here while the first builds the tables (opened to append: never cut)
        if not _has_tables(db):
            client(uri).search_experiments(max_results=1)


def _has_tables(db: Path) -> bool:
    """Whether the sqlite file ``db`` holds MLflow's tables (their schema version table)."""
    if not db.is_file() or db.stat().st_size == 0:
        return False
    try:
        with closing(sqlite3.connect(f"{db.as_uri()}?mode=ro", uri=True, timeout=STORE_TIMEOUT_S)) as con:
            found = con.execute("SELECT 1 FROM sqlite_master WHERE name = 'alembic_version'").fetchone()
    except sqlite3.Error:
        return False
    return found is not None


def _check_socket(where: str, host: str, port: int, timeout: float) -> None:
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as e:
        raise PreflightError(f"{where}: cannot connect to {host}:{port} ({e}; waited up to {timeout:g} s)") from None
