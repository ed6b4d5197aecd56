"""The MLflow store: where it is, a client for it, and what the project reads and writes in it through MLflow's
public API (`MlflowClient`) only. ``mlflow`` is imported lazily inside functions: it takes over a second to import
and ``import emml`` must stay fast.

* Default store is ``sqlite:///<project root>/mlflow.db`` (the plain file store is deprecated); any other backend
  (a shared ``mlflow server``) is a matter of the ``MLFLOW_TRACKING_URI`` environment variable.
* Writes go through ``MlflowClient.log_batch``, which splits them into calls of MLflow's limits; SQLite "database is
  locked" errors (many concurrent writers) are retried with backoff (`retry`).
* Once the process is stopping (Ctrl-C, SIGTERM: emml/envs/stops.py), a call to the store gets `STOP_GRACE_S` more
  seconds and is then given up (`StoreGaveUp`): a store locked by another process, whose every try waits MLflow's
  20 s busy timeout, held a stopped training for 3 minutes (issue 85). From the main thread each try runs in a
  helper thread that the main thread waits on, so that it can be given up, and never cut in the middle.
* :func:`metric_history` returns full curves (``search_runs`` only keeps the latest value per metric).
"""

from __future__ import annotations

import logging
import os
import random
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from emml.config.paths import project_root
from emml.envs.stops import stop_requested

T = TypeVar("T")

MAX_PARAM_LEN = 6000  # mlflow.utils.validation.MAX_PARAM_VAL_LENGTH
MAX_TAG_LEN = 8000  # mlflow.utils.validation.MAX_TAG_VAL_LENGTH


def tracking_uri() -> str:
    """``$MLFLOW_TRACKING_URI`` if set, else ``sqlite:///<project root>/mlflow.db``."""
    env = os.environ.get("MLFLOW_TRACKING_URI")
    if env:
        return env
    return f"sqlite:///{project_root() / 'mlflow.db'}"


def sqlite_path(uri: str) -> Path | None:
    """Filesystem path of a ``sqlite:///`` database (None for other backends / in-memory)."""
    prefix = "sqlite:///"
    if not uri.startswith(prefix):
        return None
    path = uri[len(prefix) :].split("?", 1)[0]
    if not path or path == ":memory:":
        return None
    return Path(path).resolve()


class _RaisedAnyway(logging.Filter):
    """Drops MLflow's log of a database error it raises anyway: ``mlflow.store.db.utils`` logs every sqlalchemy
    OperationalError (database locked, disk full) with its traceback, ~40 lines, before raising it as the
    MlflowException the caller handles; the project says it in one line (issue 85: a full disk during `emml
    import-runs` printed 95 lines of it before its own line, a locked store ~1,600)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith("SQLAlchemy database error.")


_FILTER = _RaisedAnyway()


def client(uri: str | None = None):
    """MlflowClient for ``uri`` (default `tracking_uri`); creates the sqlite file's directory if missing. MLflow's log
    of the errors it raises is kept out of the output (`_RaisedAnyway`)."""
    from mlflow import MlflowClient

    logging.getLogger("mlflow.store.db.utils").addFilter(_FILTER)  # once: a filter is added only if not there
    uri = uri or tracking_uri()
    db = sqlite_path(uri)
    if db is not None:
        db.parent.mkdir(parents=True, exist_ok=True)
    return retry(lambda: MlflowClient(tracking_uri=uri))


def _is_lock_error(exc: BaseException) -> bool:
    text = str(exc).lower()
    return "database is locked" in text or "database table is locked" in text


STOP_GRACE_S = 3.0
"""Seconds a call to the store may still take once the process is stopping, counted from the stop or from the call's
start, whichever is later: the in-flight write and then the run's end (KILLED) each get this long, within the 8 s a
campaign's pool gives a stopped run (emml/experiments/pool.py, STOP_GRACE_S)."""
POLL_S = 0.05
"""How often the main thread looks whether a call running in its helper thread is to be given up."""


class StoreGaveUp(RuntimeError):
    """The store did not answer within `STOP_GRACE_S` of a stop: the call is given up (its helper thread left to
    finish or not; the process is ending)."""


def _give_up_if_stopping(started: float) -> None:
    stop = stop_requested()
    if stop is not None and time.monotonic() > max(stop, started) + STOP_GRACE_S:
        raise StoreGaveUp(f"the MLflow store did not answer within {STOP_GRACE_S:g} s of the stop (locked or busy)")


def _attempt(fn: Callable[[], T], started: float) -> T:
    """``fn()``; from the main thread, run in a daemon helper thread that is given up (`StoreGaveUp`) once the process
    has been stopping for `STOP_GRACE_S` (a signal the main thread gets meanwhile never cuts the write itself)."""
    if threading.current_thread() is not threading.main_thread():
        return fn()
    box: dict = {}

    def call():
        try:
            box["value"] = fn()
        except BaseException as e:  # noqa: BLE001 - raised again in the main thread
            box["error"] = e

    helper = threading.Thread(target=call, name="emml-store-call", daemon=True)
    helper.start()
    while True:
        helper.join(POLL_S)
        if not helper.is_alive():
            break
        _give_up_if_stopping(started)
    if "error" in box:
        raise box["error"]
    return box["value"]


def _wait(seconds: float, started: float) -> None:
    """Sleep ``seconds`` between tries, given up as `_attempt` is."""
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        _give_up_if_stopping(started)
        time.sleep(min(left, POLL_S))
    _give_up_if_stopping(started)


def retry(fn: Callable[[], T], attempts: int = 8, base_delay: float = 0.1) -> T:
    """Call ``fn``; retry SQLite lock errors with jittered exponential backoff. Once the process is stopping, given up
    `STOP_GRACE_S` after the stop (or this call's start, if later) with `StoreGaveUp`."""
    started = time.monotonic()
    for i in range(attempts):
        try:
            return _attempt(fn, started)
        except StoreGaveUp:
            raise
        except Exception as exc:  # mlflow wraps sqlalchemy errors in MlflowException
            if not _is_lock_error(exc) or i == attempts - 1:
                raise
            _wait(base_delay * (2**i) * (0.5 + random.random()), started)
    raise AssertionError("unreachable")


def log_batch(mlflow_client, run_id: str, metrics=(), params=(), tags=()) -> None:
    """``MlflowClient.log_batch`` for any number of entities (MLflow splits them into calls of its limits), retried
    whole on a lock: a retry logs again what a first call's earlier chunks wrote, which MLflow's store keeps once (an
    identical metric point is skipped, a param may be logged again with its value, a tag is overwritten)."""
    metrics, params, tags = list(metrics), list(params), list(tags)
    retry(lambda: mlflow_client.log_batch(run_id, metrics=metrics, params=params, tags=tags))


def last_points(points: Iterable[tuple[int, str, float]], when: Callable[[int], int] | None = None):
    """(key, step, value, timestamp) per key and step (the last value given), by key then step, each timestamped
    ``when(step)`` (ms; default now)."""
    now = int(time.time() * 1000)
    last = {(k, st): v for st, k, v in points}
    return [(k, st, v, when(st) if when else now) for (k, st), v in sorted(last.items())]


def log_points(
    mlflow_client, run_id: str, points: Iterable[tuple[int, str, float]], when: Callable[[int], int] | None = None
) -> int:
    """Log (step, key, value) points into ``run_id``, one per key and step (the last), timestamped ``when(step)`` (ms;
    default now), with `log_batch`; returns how many were logged."""
    from mlflow.entities import Metric

    items = [Metric(k, v, ts, st) for k, st, v, ts in last_points(points, when)]
    log_batch(mlflow_client, run_id, metrics=items)
    return len(items)


def has_run(run_id: str, uri: str | None = None, mlflow_client=None) -> bool:
    """Whether the store holds run ``run_id`` (deleted or not)."""
    from mlflow.exceptions import MlflowException

    mlflow_client = mlflow_client or client(uri)
    try:
        retry(lambda: mlflow_client.get_run(run_id))
        return True
    except MlflowException as e:
        if e.error_code == "RESOURCE_DOES_NOT_EXIST":
            return False
        raise


def metric_history(run_id: str, key: str, uri: str | None = None) -> list[tuple[int, float]]:
    """Full curve of metric ``key`` as ``[(step, value), ...]`` sorted by step (then time)."""
    mlflow_client = client(uri)
    hist = retry(lambda: mlflow_client.get_metric_history(run_id, key))
    return [(m.step, m.value) for m in sorted(hist, key=lambda m: (m.step, m.timestamp))]


def _quote(value: Any) -> str:
    return "'" + str(value).replace("\\", "\\\\").replace("'", "\\'") + "'"


def find_runs(experiment: str, filter_tags: Mapping[str, Any] | None = None, uri: str | None = None) -> list[dict]:
    """Runs of ``experiment`` whose tags equal ``filter_tags`` (all pages).

    Each run is a dict: ``run_id``, ``run_name``, ``status``, ``start_time``
    (ms), ``tags``, ``params`` and ``metrics`` (latest value of each). Missing
    experiment -> empty list.
    """
    mlflow_client = client(uri)
    exp = retry(lambda: mlflow_client.get_experiment_by_name(experiment))
    if exp is None:
        return []
    filt = " and ".join(f"tags.`{k}` = {_quote(v)}" for k, v in (filter_tags or {}).items())
    runs: list[dict] = []
    token = None
    while True:
        page = retry(
            lambda token=token: mlflow_client.search_runs([exp.experiment_id], filter_string=filt, page_token=token)
        )
        for r in page:
            runs.append(
                {
                    "run_id": r.info.run_id,
                    "run_name": r.info.run_name,
                    "status": r.info.status,
                    "start_time": r.info.start_time,
                    "tags": dict(r.data.tags),
                    "params": dict(r.data.params),
                    "metrics": dict(r.data.metrics),
                }
            )
        token = page.token
        if not token:
            return runs
