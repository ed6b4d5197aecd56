"""A run's end the store did not take in time (emml/runs/pending_ends.py, issue 85): recorded by `Tracker.finish`
when the store is given up, written by the next start against that store, never over a run being trained again
(its run dir's lock held) nor over a run that ended meanwhile; a resumed run drops its own record."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

import emml.runs.tracking as tracking_module
from emml.runs import pending_ends
from emml.runs.atomic import STALE_TMP_S
from emml.runs.runlock import LOCK, take_lock
from emml.runs.store import StoreGaveUp, client
from emml.runs.tracking import Tracker


def _status(uri, run_id) -> tuple[str, int | None]:
    info = client(uri).get_run(run_id).info
    return info.status, info.end_time


def _running(tracking, run_dir: Path) -> Tracker:
    tracker = Tracker(tracking["uri"])
    run_dir.mkdir(parents=True, exist_ok=True)
    tracker.mirror_to(run_dir / "metrics.csv")
    tracker.start("test", run_dir.name)
    return tracker


def test_an_end_given_up_is_recorded_and_the_next_start_writes_it(tracking, tmp_path, monkeypatch):
    tracker = _running(tracking, tmp_path / "runs" / "a")
    real = tracking_module.retry

    def gave_up(fn, *args, **kwargs):
        raise StoreGaveUp("the MLflow store did not answer within 3 s of the stop (locked or busy): given up")

    monkeypatch.setattr(tracking_module, "retry", gave_up)
    with pytest.warns(UserWarning, match="left RUNNING: .* marked KILLED at the next start"):
        tracker.abort(KeyboardInterrupt())
    monkeypatch.setattr(tracking_module, "retry", real)
    (record,) = pending_ends.pending(tracking["uri"])
    assert record["run_id"] == tracker.run_id and record["status"] == "KILLED"
    assert record["run_dir"] == str(tmp_path / "runs" / "a")
    assert _status(tracking["uri"], tracker.run_id)[0] == "RUNNING"
    Tracker(tracking["uri"]).start("test", "the next start")
    assert _status(tracking["uri"], tracker.run_id) == ("KILLED", record["end_time"])  # when it stopped, not now
    assert pending_ends.pending(tracking["uri"]) == []


def test_a_run_being_trained_again_or_ended_meanwhile_is_left_as_it_is(tracking, tmp_path):
    busy_dir, ended_dir = tmp_path / "runs" / "busy", tmp_path / "runs" / "ended"
    busy, ended = _running(tracking, busy_dir), _running(tracking, ended_dir)
    for tracker, folder in ((busy, busy_dir), (ended, ended_dir)):
        pending_ends.record_end(tracking["uri"], tracker.run_id, "KILLED", 1, folder)
    ended.finish("FINISHED")
    fd = take_lock(busy_dir / LOCK)  # a training holds the run (its lock; here this process's)
    try:
        assert pending_ends.apply_ends(tracking["uri"]) == []
        assert _status(tracking["uri"], busy.run_id)[0] == "RUNNING"  # its trainer sets its status
        assert [r["run_id"] for r in pending_ends.pending(tracking["uri"])] == [busy.run_id]  # kept for later
    finally:
        os.close(fd)
    assert _status(tracking["uri"], ended.run_id)[0] == "FINISHED"  # not overwritten, its record dropped
    assert pending_ends.apply_ends(tracking["uri"]) == [busy.run_id]  # its lock free: now written
    assert _status(tracking["uri"], busy.run_id) == ("KILLED", 1)


def test_a_resumed_run_drops_its_own_record(tracking, tmp_path):
    stopped = _running(tracking, tmp_path / "runs" / "r")
    pending_ends.record_end(tracking["uri"], stopped.run_id, "KILLED", 1, tmp_path / "runs" / "r")
    fd = take_lock(tmp_path / "runs" / "r" / LOCK)  # the resuming trainer holds its run (hold_run)
    try:
        resumed = Tracker(tracking["uri"])
        resumed.start("test", "r", run_id=stopped.run_id)
    finally:
        os.close(fd)
    assert pending_ends.pending(tracking["uri"]) == []  # dropped, not left for a later start to mark KILLED
    assert _status(tracking["uri"], stopped.run_id)[0] == "RUNNING"  # the resumed run's, not the record's KILLED


def test_records_are_per_store(tracking, tmp_path):
    tracker = _running(tracking, tmp_path / "runs" / "s")
    pending_ends.record_end(tracking["uri"], tracker.run_id, "KILLED", 1)
    other = f"sqlite:///{tmp_path}/other.db"
    assert pending_ends.pending(other) == [] and len(pending_ends.pending(tracking["uri"])) == 1
    assert pending_ends.ends_dir(tracking["uri"]) != pending_ends.ends_dir(other)


def test_a_temp_file_a_kill_left_is_removed_once_stale_and_a_fresh_one_kept(tracking):
    folder = pending_ends.ends_dir(tracking["uri"])
    folder.mkdir(parents=True, exist_ok=True)
    stale, fresh = folder / ".abc.tmp", folder / ".def.tmp"
    for tmp in (stale, fresh):
        tmp.write_text('{"run_id": ')  # a record_end killed mid-write
    old = time.time() - STALE_TMP_S - 10
    os.utime(stale, (old, old))
    assert pending_ends.apply_ends(tracking["uri"]) == [] and pending_ends.pending(tracking["uri"]) == []
    assert not stale.exists() and fresh.exists()  # a record being written now is left to its writer
    fresh.unlink()
