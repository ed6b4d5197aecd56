"""A run's end that the store did not take: recorded on disk, applied at the next start.

A stopped training gives its MLflow store a few seconds (emml/runs/store.py, `STOP_GRACE_S`); when the store is
locked or busy past them, the run is left RUNNING in the store and its end (KILLED, with the time it ended) is
written here instead, so that the process ends within seconds and still says how to resume (issue 85). The next
`Tracker.start` against the same store applies it (`apply_ends`), unless the run is being trained again (its run
dir's lock is held: that training sets the status itself) or has ended meanwhile (status no longer RUNNING); a run
resumed drops its own record first (`drop_end`).

Records live per user and per store under the temp dir (``emml-pending-ends-<uid>/<store key>/<run id>.json``): a
store on a server has no folder of its own, and a record is about this machine's processes.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
import time
from pathlib import Path

from emml.runs import store
from emml.runs.atomic import sweep_stale
from emml.runs.runlock import LOCK, lock_holder


def store_key(uri: str | None) -> str:
    """The folder name of a store's records: a hash of its URI (a sqlite file by its resolved path)."""
    uri = uri or store.tracking_uri()
    db = store.sqlite_path(uri)
    return hashlib.sha1((f"sqlite:///{db}" if db is not None else uri).encode()).hexdigest()[:16]


def ends_dir(uri: str | None) -> Path:
    """Where the pending ends of the store ``uri`` (default: `store.tracking_uri`) are recorded."""
    return Path(tempfile.gettempdir()) / f"emml-pending-ends-{os.getuid()}" / store_key(uri)


def record_end(uri: str | None, run_id: str, status: str, end_time: int, run_dir: Path | None = None) -> Path:
    """Record that MLflow run ``run_id`` ended with ``status`` at ``end_time`` (ms since the epoch), its run dir
    ``run_dir`` (whose lock says whether it is being trained again); written atomically. Returns the record."""
    folder = ends_dir(uri)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{run_id}.json"
    payload = {"run_id": run_id, "status": status, "end_time": end_time, "run_dir": str(run_dir) if run_dir else None}
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".", suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        json.dump(payload, f)
    os.replace(tmp, path)
    return path


def drop_end(uri: str | None, run_id: str) -> None:
    """Forget the pending end of ``run_id`` (it is being resumed: its status is set again)."""
    with contextlib.suppress(FileNotFoundError):
        (ends_dir(uri) / f"{run_id}.json").unlink()


def pending(uri: str | None) -> list[dict]:
    """The pending ends recorded for the store ``uri``, oldest first; a record that does not read is skipped (it
    is being written, or torn: `apply_ends` leaves it)."""
    folder = ends_dir(uri)
    out = []
    for path in sorted(folder.glob("*.json"), key=lambda p: p.stat().st_mtime) if folder.is_dir() else ():
        with contextlib.suppress(OSError, ValueError, KeyError):
            record = json.loads(path.read_text())
            out.append({**record, "path": path, "status": str(record["status"]), "run_id": str(record["run_id"])})
    return out


def apply_ends(uri: str | None = None, mlflow_client=None) -> list[str]:
    """Mark each pending run of the store ``uri`` ended as recorded, if it is still RUNNING and nobody trains it (its
    run dir's lock free), and drop the record; a run gone from the store drops its record too; a record's temp file
    older than `STALE_TMP_S` (emml/runs/atomic.py) goes. Returns the run ids marked."""
    from mlflow.exceptions import MlflowException

    sweep_stale(ends_dir(uri), ".*.tmp")  # what a kill inside `record_end` left
    records = pending(uri)
    if not records:
        return []
    mlflow_client = mlflow_client or store.client(uri)
    marked = []
    for record in records:
        run_dir = record.get("run_dir")
        if run_dir and lock_holder(Path(run_dir) / LOCK) is not None:
            continue  # being trained (or still ending): its trainer sets the status
        try:
            run = store.retry(lambda r=record: mlflow_client.get_run(r["run_id"]))
        except MlflowException as e:
            if e.error_code != "RESOURCE_DOES_NOT_EXIST":
                raise
            run = None
        if run is not None and run.info.status == "RUNNING":
            end = int(record.get("end_time") or time.time() * 1000)
            store.retry(lambda r=record, end=end: mlflow_client.set_terminated(r["run_id"], r["status"], end))
            marked.append(record["run_id"])
        with contextlib.suppress(FileNotFoundError):
            record["path"].unlink()
    return marked
