"""emml.runs.tracking against a throwaway sqlite store (one module: mlflow import + migration are slow)."""

import pytest

from emml.runs import store, tracking


@pytest.fixture(scope="module")
def uri(tmp_path_factory):
    # a directory that does not exist yet: the tracker must create it
    db = tmp_path_factory.mktemp("mlf") / "missing" / "sub" / "mlflow.db"
    return f"sqlite:///{db}"


@pytest.fixture(autouse=True)
def _env(uri, monkeypatch):
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    monkeypatch.setenv("MLFLOW_DISABLE_TELEMETRY", "true")


def test_tracking_uri_default_and_env(monkeypatch, uri):
    assert store.tracking_uri() == uri
    monkeypatch.delenv("MLFLOW_TRACKING_URI")
    default = store.tracking_uri()
    assert default.startswith("sqlite:///") and default.endswith("/mlflow.db")


def test_flatten():
    assert tracking.flatten({"ppo": {"lr": 0.1, "clip": {"a": 1}}, "seed": 3}) == {
        "ppo.lr": "0.1",
        "ppo.clip.a": "1",
        "seed": "3",
    }


def test_start_log_resume_find(tmp_path, uri):
    t = tracking.Tracker()
    rid = t.start("exp-a", "run1", tags={"model": "dual", "seed": 1}, params={"ppo": {"lr": 2.5e-4}, "seed": 1})
    assert t.run_id == rid
    t.log_metrics({"loss": 1.0, "acc": 0.1}, step=10)
    t.log_metrics({"loss": 0.5, "acc": 0.2}, step=20)
    art = tmp_path / "note.txt"
    art.write_text("hi")
    t.log_artifact(art)
    t.finish("KILLED")

    t2 = tracking.Tracker()
    with pytest.warns(UserWarning, match="ppo.lr"):
        rid2 = t2.start("exp-a", "run1", tags={"resumed": "yes"}, params={"ppo": {"lr": 1.0}, "extra": 5}, run_id=rid)
    assert rid2 == rid
    t2.log_metrics({"loss": 0.25}, step=30)
    t2.finish()

    assert store.metric_history(rid, "loss") == [(10, 1.0), (20, 0.5), (30, 0.25)]
    tracking.Tracker().start("exp-a", "run2", tags={"model": "ga", "seed": 1}, params={})
    runs = store.find_runs("exp-a", {"model": "dual"})
    assert [r["run_id"] for r in runs] == [rid]
    r = runs[0]
    assert r["status"] == "FINISHED" and r["tags"]["resumed"] == "yes"
    assert r["params"] == {"ppo.lr": "0.00025", "seed": "1", "extra": "5"}
    assert r["metrics"]["loss"] == 0.25
    assert len(store.find_runs("exp-a", {"seed": 1})) == 2
    assert store.find_runs("no-such-exp", {}) == []
    # artifacts go beside the (previously missing) db directory, not into the cwd
    stored = list((tmp_path_db(uri) / "mlartifacts").rglob("note.txt"))
    assert len(stored) == 1 and stored[0].read_text() == "hi" and rid in str(stored[0])


def tmp_path_db(uri):
    from pathlib import Path

    return Path(uri[len("sqlite:///") :]).parent


def test_retry_on_database_locked(monkeypatch):
    monkeypatch.setattr(store.time, "sleep", lambda s: None)
    calls = []

    def flaky():
        calls.append(1)
        if len(calls) < 3:
            raise RuntimeError("(sqlite3.OperationalError) database is locked")
        return "ok"

    assert store.retry(flaky) == "ok" and len(calls) == 3
    with pytest.raises(ValueError):
        store.retry(lambda: (_ for _ in ()).throw(ValueError("other")))


def test_a_run_exports_its_whole_curve_to_a_mirror_file(tmp_path):
    from emml.runs.mirror import read_mirror
    from emml.runs.tracking import Tracker

    t = Tracker(f"sqlite:///{tmp_path}/m.db")
    run_id = t.start("exp", "r")
    for step in (64, 128):
        t.log_metrics({"a": step / 2, "b": 1.0}, step=step)
    t.finish()
    t.mirror_to(tmp_path / "metrics.csv")
    assert t.export_to_mirror(run_id) == 4
    assert read_mirror(tmp_path / "metrics.csv") == [(64, "a", 32.0), (64, "b", 1.0), (128, "a", 64.0), (128, "b", 1.0)]
    with open(tmp_path / "metrics.csv", "a") as f:
        f.write("192,a,9")  # a line cut short by a kill: skipped
    assert len(read_mirror(tmp_path / "metrics.csv")) == 4


def test_a_run_that_fails_once_created_ends_failed_not_running(monkeypatch):
    import errno

    t = tracking.Tracker()
    real = t._client.log_batch

    def no_room_for_params(run_id, metrics=(), params=(), tags=()):
        if params:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(run_id, metrics=metrics, params=params, tags=tags)

    monkeypatch.setattr(t._client, "log_batch", no_room_for_params)
    with pytest.raises(OSError, match="No space left"):
        t.start("exp-fail", "r", params={"a": 1})
    assert [r["status"] for r in store.find_runs("exp-fail")] == ["FAILED"]


def test_abort_ends_a_started_run_and_never_hides_the_cause(monkeypatch):
    tracking.Tracker().abort(RuntimeError("never started"))  # no run: nothing to end
    t = tracking.Tracker()
    t.start("exp-abort", "signalled")
    t.abort(SystemExit(1))  # a termination signal (install_signal_handlers raises SystemExit)
    broken = tracking.Tracker()
    broken.start("exp-abort", "store-down")

    def store_down(*args, **kwargs):
        raise RuntimeError("store down")

    monkeypatch.setattr(broken._client, "set_terminated", store_down)
    with pytest.warns(UserWarning, match=r"could not be marked ended: RuntimeError: store down"):
        broken.abort(ValueError("the cause"))
    assert {r["run_name"]: r["status"] for r in store.find_runs("exp-abort")}["signalled"] == "KILLED"


def test_a_full_disk_leaves_the_mirror_without_a_half_line(tmp_path, monkeypatch):
    import builtins
    import errno

    from emml.runs.diskspace import NoSpaceError
    from emml.runs.mirror import read_mirror
    from emml.runs.tracking import Tracker

    class Filling:
        """A file whose first write lands in part, the next fails: the disk filled in the middle of a batch."""

        def __init__(self, f):
            self.f, self.writes = f, 0

        def write(self, data):
            self.writes += 1
            if self.writes == 1:
                return self.f.write(bytes(data[:5]))
            raise OSError(errno.ENOSPC, "No space left on device")

        def __getattr__(self, name):
            return getattr(self.f, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

    t = Tracker(f"sqlite:///{tmp_path}/m.db")
    t.start("exp", "r")
    mirror = tmp_path / "metrics.csv"
    t.mirror_to(mirror)
    t.log_metrics({"a": 1.0}, step=64)
    before = mirror.read_bytes()
    monkeypatch.setattr("emml.runs.mirror.open", lambda *a, **k: Filling(builtins.open(*a, **k)), raising=False)
    with pytest.raises(NoSpaceError, match=rf"^no space left on {tmp_path} \(writing metrics.csv, left as it was\)"):
        t.log_metrics({"a": 2.0, "b": 3.0}, step=128)
    monkeypatch.undo()
    assert mirror.read_bytes() == before  # cut back to the last whole line
    t.log_metrics({"a": 4.0}, step=192)
    assert read_mirror(mirror) == [(64, "a", 1.0), (192, "a", 4.0)]
    t.finish()


def test_a_run_dir_from_another_store_resumed_twice_continues_one_run(tmp_path):
    """Killed before its first checkpoint (which still names the other store's run), a resumed run dir resumes the
    run its first resume made here, not a third one (stored_run: tag RESUMED_FROM)."""
    import warnings

    mirror = tmp_path / "metrics.csv"
    mirror.write_text("step,key,value\n64,loss,1.0\n")

    def resume(step: int, value: float) -> str:
        t = tracking.Tracker()
        t.mirror_to(mirror)
        t.resume_after(64)
        run_id = t.start("exp-resumed", "r", run_id="f" * 32)
        t.log_metrics({"loss": value}, step=step)
        t.finish("KILLED")
        return run_id

    with pytest.warns(UserWarning, match="is not in this store"):
        first = resume(128, 0.5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing replayed again
        assert resume(192, 0.25) == first
    [run] = store.find_runs("exp-resumed")
    assert run["tags"][tracking.RESUMED_FROM] == "f" * 32
    assert store.metric_history(first, "loss") == [(64, 1.0), (128, 0.5), (192, 0.25)]


def test_a_batch_retried_after_a_lock_midway_logs_each_point_once(tmp_path, monkeypatch):
    """`store.log_batch` hands MLflow every entity at once (MLflow splits them into calls of its limits: 1,000
    metrics, 100 params) and retries the whole call on a lock; a lock on the second of those calls makes the retry log
    again what the first wrote, which the store must keep once: each step once in the curve, each param once."""
    from mlflow.entities import Metric, Param

    monkeypatch.setattr(store.time, "sleep", lambda s: None)
    client = store.client(f"sqlite:///{tmp_path}/m.db")
    run_id = client.create_run(client.create_experiment("e")).info.run_id
    real, calls = client._tracking_client.store.log_batch, []

    def locked_once(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("(sqlite3.OperationalError) database is locked")
        return real(*args, **kwargs)

    monkeypatch.setattr(client._tracking_client.store, "log_batch", locked_once)
    metrics = [Metric("a", float(step), 1000 + step, step) for step in range(2500)]
    params = [Param(f"p{i}", str(i)) for i in range(150)]
    store.log_batch(client, run_id, metrics=iter(metrics), params=iter(params))
    assert len(calls) > 3  # split by MLflow, and the second call refused once
    history = client.get_metric_history(run_id, "a")
    assert sorted(m.step for m in history) == list(range(2500))
    assert client.get_run(run_id).data.params == {f"p{i}": str(i) for i in range(150)}
