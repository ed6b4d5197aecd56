"""The store's calls once the process is stopping (emml/runs/store.py, issue 85): given up `STOP_GRACE_S` after the
stop (or after the call's start, when later) instead of MLflow's 20 s busy timeout per try, 8 tries; untouched when
no stop came."""

from __future__ import annotations

import threading
import time

import pytest

from emml.envs import stops
from emml.runs import store


@pytest.fixture
def grace(monkeypatch):
    monkeypatch.setattr(store, "STOP_GRACE_S", 0.5)
    yield 0.5
    stops.reset_stop()


def _blocked(event: threading.Event):
    def call():
        event.wait(30)  # a store that does not answer (locked by another process)
        return "answered"

    return call


def test_a_call_that_does_not_answer_is_given_up_within_the_grace_of_a_stop(grace):
    never = threading.Event()
    threading.Timer(0.3, stops.note_stop).start()  # the stop comes while the call waits
    started = time.monotonic()
    with pytest.raises(store.StoreGaveUp, match="did not answer within 0.5 s of the stop"):
        store.retry(_blocked(never))
    took = time.monotonic() - started
    never.set()
    assert 0.3 + grace <= took < 0.3 + grace + 1.0, took


def test_a_call_started_after_the_stop_gets_its_own_grace(grace):
    stops.note_stop()
    time.sleep(2 * grace)  # the stop is long past: the run's end still gets its seconds
    answer = threading.Event()
    threading.Timer(grace / 2, answer.set).start()
    assert store.retry(_blocked(answer)) == "answered"


def test_without_a_stop_a_slow_call_is_waited_for_and_a_lock_error_retried(grace):
    answer = threading.Event()
    threading.Timer(2 * grace, answer.set).start()  # slower than the grace: no stop, so waited for
    assert store.retry(_blocked(answer)) == "answered"
    tries = []

    def locked_twice():
        tries.append(1)
        if len(tries) < 3:
            raise RuntimeError("(sqlite3.OperationalError) database is locked")
        return "written"

    assert store.retry(locked_twice, base_delay=0.01) == "written" and len(tries) == 3
    stops.note_stop()
    time.sleep(2 * grace)
    tries.clear()

    def always_locked():
        tries.append(1)
        time.sleep(grace / 4)
        raise RuntimeError("database is locked")

    with pytest.raises(store.StoreGaveUp):  # stopping: the retries end with the grace, not after 8 tries
        store.retry(always_locked, base_delay=0.01)
    assert 2 <= len(tries) < 8


def test_an_error_of_the_call_is_raised_as_it_is(grace):
    def fails():
        raise ValueError("not a lock error")

    with pytest.raises(ValueError, match="not a lock error"):
        store.retry(fails)


WRITE_PAST_THE_LIMIT = """
import resource, signal, sys
from mlflow.entities import Metric
from emml.runs import store
uri, run_id = sys.argv[1], sys.argv[2]
mlflow_client = store.client(uri)
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails (EFBIG) instead of killing
resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))  # as a full disk: no page of the store can be written
try:
    store.log_batch(mlflow_client, run_id, metrics=[Metric(f"m{i}", 1.0, 0, i) for i in range(2000)])
except Exception as e:
    print("raised:", type(e).__name__, "sqlite3.OperationalError" in str(e))
"""


def test_mlflows_own_log_of_a_database_error_is_kept_out_and_the_error_still_raised(tracking):
    """Issue 85: MLflow logs every sqlite OperationalError with its traceback (~40 lines) before raising it; a full
    disk during `emml import-runs` printed 95 such lines before the project's one. The error still comes as the
    exception the caller turns into its line."""
    import subprocess
    import sys

    from emml.runs.tracking import Tracker

    tracker = Tracker(tracking["uri"])
    tracker.start("test", "full")
    out = subprocess.run(
        [sys.executable, "-c", WRITE_PAST_THE_LIMIT, tracking["uri"], tracker.run_id],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert "raised: MlflowException True" in out.stdout, out.stdout + out.stderr[-3000:]
    assert "SQLAlchemy database error" not in out.stderr and "Traceback" not in out.stderr, out.stderr[-3000:]
