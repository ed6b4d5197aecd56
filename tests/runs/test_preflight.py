"""Pre-flight (emml/runs/preflight.py) by fault injection: a broken store, an unwritable folder, a broken results CSV or
a bad field is refused in one line naming it, with exit code 2, in seconds, before any engine, model or MLflow run —
nothing is written."""

from __future__ import annotations

import re
import socket
import sqlite3
import time
from contextlib import closing
from pathlib import Path

import pytest
from typer.testing import CliRunner

from emml.cli import app
from emml.runs.preflight import PreflightError, check_store, check_writable

runner = CliRunner()


def _refused_port() -> int:
    """A local port nothing listens on (bound then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stores(tmp_path: Path) -> dict[str, str]:
    """URI → what the message must say, for each kind of broken store."""
    (tmp_path / "junk.db").write_text("not a database, just text\n" * 4)
    (tmp_path / "dir.db").mkdir()
    good = tmp_path / "good.db"
    with closing(sqlite3.connect(good)) as con:
        con.execute("CREATE TABLE t (x)")
    raw = good.read_bytes()
    (tmp_path / "damaged.db").write_bytes(raw[:16] + b"\xff" * (len(raw) - 16))
    port = _refused_port()
    return {
        "sqlite:////proc/mlflow.db": "cannot create files in /proc",
        f"sqlite:///{tmp_path}/junk.db": f"{tmp_path}/junk.db is not an SQLite database",
        f"sqlite:///{tmp_path}/dir.db": f"{tmp_path}/dir.db is not a file",
        f"sqlite:///{tmp_path}/damaged.db": f"{tmp_path}/damaged.db is a damaged SQLite database",
        "file:///proc/mlruns": "cannot create files in /proc",
        f"http://127.0.0.1:{port}": "cannot be reached",
        f"postgresql://u@127.0.0.1:{port}/db": f"cannot connect to 127.0.0.1:{port}",
    }


@pytest.fixture
def no_retries(monkeypatch):
    """What made a broken store take ~100 s was MLflow's client retrying with back-off; the pre-flight checks must
    neither reach MLflow nor wait between attempts. Observed as events, not by a clock (issue 66: a 3 s bound is at
    the mercy of the machine's load): importing mlflow and any sleep fail the test."""
    import sys

    def sleep(seconds):
        raise AssertionError(f"the pre-flight check slept {seconds} s: a retry")

    monkeypatch.setitem(sys.modules, "mlflow", None)  # `import mlflow` raises ImportError
    monkeypatch.setattr(time, "sleep", sleep)


def test_a_broken_store_is_named_in_one_line_within_seconds(tmp_path, no_retries):
    for uri, why in _stores(tmp_path).items():
        with pytest.raises(PreflightError) as e:
            check_store(uri)
        assert str(e.value).startswith(f"MLflow store {uri}: ") and why in str(e.value), str(e.value)
        assert "\n" not in str(e.value)


def test_a_usable_store_passes_and_nothing_is_created(tmp_path):
    good = tmp_path / "good.db"
    with closing(sqlite3.connect(good)) as con:
        con.execute("CREATE TABLE t (x)")
    (tmp_path / "empty.db").write_bytes(b"")  # SQLite reads an empty file as an empty database
    for uri in (f"sqlite:///{good}", f"sqlite:///{tmp_path}/empty.db", f"sqlite:///{tmp_path}/new/sub/mlflow.db"):
        check_store(uri)
    check_store("sqlite://")  # in memory
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.db", "good.db"]  # no probe, no folder, no db left
    with closing(sqlite3.connect(good)) as con:  # a writer holding the lock: the tracker waits for it, so it passes
        con.execute("BEGIN EXCLUSIVE")
        check_store(f"sqlite:///{good}", timeout=0.2)


def test_check_writable_names_the_setting_and_the_folder(tmp_path):
    assert check_writable("run_root='x'", tmp_path / "a" / "b") == tmp_path
    assert list(tmp_path.iterdir()) == []  # the probe is gone, nothing was made
    (tmp_path / "file").write_text("")
    with pytest.raises(PreflightError, match=rf"^run_root='x': {re.escape(str(tmp_path))}/file is not a directory$"):
        check_writable("run_root='x'", tmp_path / "file" / "runs")
    with pytest.raises(PreflightError, match=r"^results_root='/proc/r': cannot create files in /proc \("):
        check_writable("results_root='/proc/r'", "/proc/r/t")


def _train(tracking, *extra: str):
    roots = ["--set", f"run_root={tracking['run_root']}", "--set", f"results_root={tracking['results_root']}"]
    return runner.invoke(app, ["train", "--profile", "smoke", "--table", "test", *roots, *extra])


def _refused(result, message: str) -> None:
    """Exit 2 and exactly one line, the error."""
    assert result.exit_code == 2, result.output
    assert result.output.startswith(f"error: {message}") and result.output.count("\n") == 1, result.output


def _nothing_written(tracking, tmp_path: Path) -> None:
    assert not Path(tracking["run_root"]).exists()
    assert not (tmp_path / "mlflow.db").exists()  # the test's store: no MLflow run was created (not even the file)


def _bad_csv(tracking, content: bytes) -> Path:
    path = Path(tracking["results_root"]) / "test" / "smoke.csv"
    path.parent.mkdir(parents=True)
    path.write_bytes(content)
    return path


@pytest.mark.parametrize(
    "args, message",
    [
        (["--seed", "-1"], "seed=-1 must be >= 0"),
        (["--table", ""], "table='' must be a plain name: letters, digits"),
        (["--table", "../../x"], "table='../../x' must be a plain name"),
        (["--table", "a/b"], "table='a/b' must be a plain name"),
        (["--frames", "1"], "frames=1 is less than one update (num_envs × num_steps = 64); the minimum is 64"),
        (["--set", "run_root=/proc/emml-runs"], "run_root='/proc/emml-runs': cannot create files in /proc ("),
        (["--set", "results_root=/proc/emml-results"], "results_root='/proc/emml-results': cannot create files in"),
    ],
)
def test_train_refuses_bad_input_before_anything_runs(args, message, tracking, tmp_path, no_leftovers):
    result = _train(tracking, *args)
    _refused(result, message)
    _nothing_written(tracking, tmp_path)
    assert not Path(tracking["results_root"]).exists()


def test_train_refuses_a_broken_store(tracking, tmp_path, monkeypatch, no_leftovers):
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "sqlite:////proc/mlflow.db")
    t0 = time.monotonic()
    _refused(_train(tracking), "MLflow store sqlite:////proc/mlflow.db: cannot create files in /proc")
    assert time.monotonic() - t0 < 10  # MLflow's own retries took ~100 s
    _nothing_written(tracking, tmp_path)
    junk = tmp_path / "mlflow.db"
    junk.write_bytes(b"junk " * 100)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{junk}")
    _refused(_train(tracking), f"MLflow store sqlite:///{junk}: {junk} is not an SQLite database")
    assert junk.read_bytes() == b"junk " * 100 and not Path(tracking["run_root"]).exists()


@pytest.mark.parametrize(
    "content, why",
    [
        (b"run_name,seed\na,0\nb,1,extra\n", ": not a well-formed CSV: Expected 2 fields in line 3, saw 3"),
        (b"run_name,seed\na,0\nb\xff,1\n", ": line 3: not UTF-8 text"),
        (b"run_name,seed\na,0\nb,one\n", ": line 3: column 'seed' must hold an integer, found 'one'"),
        (b"", ": empty, without the header line a results CSV starts with"),
        (b"name,seed\na,0\n", ": line 1: no 'run_name' column in the header (found name, seed)"),
    ],
)
def test_train_refuses_a_broken_results_csv_naming_file_and_line(content, why, tracking, tmp_path, no_leftovers):
    path = _bad_csv(tracking, content)
    _refused(_train(tracking), f"{path}{why}")
    _nothing_written(tracking, tmp_path)
    assert path.read_bytes() == content and list(path.parent.iterdir()) == [path]


def test_run_refuses_before_its_parent_run(tracking, tmp_path, monkeypatch, no_leftovers):
    """`emml run` and the launcher: the store, the folders and the CSV are checked before the parent MLflow run."""
    from emml.experiments.launch import run_table

    monkeypatch.setattr("emml.config.paths.project_root", lambda: tmp_path)  # `emml run` writes under runs/, results/
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "sqlite:////proc/mlflow.db")
    _refused(runner.invoke(app, ["run", "table3", "--profile", "smoke"]), "MLflow store sqlite:////proc/mlflow.db")
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setenv("MLFLOW_TRACKING_URI", tracking["uri"])

    def launch(**roots):
        return run_table("table3", "smoke", jobs=1, train_fn=_never, log=lambda m: None, **roots)

    with pytest.raises(PreflightError, match=r"^run_root='/proc/r': cannot create files in /proc"):
        launch(run_root="/proc/r", results_root=tracking["results_root"])
    path = Path(tracking["results_root"]) / "table3" / "smoke.csv"
    path.parent.mkdir(parents=True)
    path.write_bytes(b"run_name,seed\na,0\nb,1,2\n")
    why = "not a well-formed CSV: Expected 2 fields in line 3, saw 3"
    with pytest.raises(ValueError, match=rf"^{re.escape(f'{path}: {why}')}"):
        launch(run_root=tracking["run_root"], results_root=tracking["results_root"])
    _nothing_written(tracking, tmp_path)


def _never(cfg, quiet=False, parent_run_id=None):
    raise AssertionError("no run may start")


@pytest.mark.parametrize("command", [["report", "table2", "--profile", "smoke"], ["reports"]])
def test_reports_refuse_a_broken_store_at_once(command, tmp_path, monkeypatch, no_leftovers):
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "sqlite:////proc/mlflow.db")
    t0 = time.monotonic()
    result = runner.invoke(app, [*command, "--out", str(tmp_path / "out")])
    _refused(result, "MLflow store sqlite:////proc/mlflow.db: cannot create files in /proc")
    assert time.monotonic() - t0 < 10 and not (tmp_path / "out").exists()
    junk = tmp_path / "mlflow.db"
    junk.write_text("junk")
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{junk}")
    _refused(runner.invoke(app, [*command, "--out", str(tmp_path / "out")]), f"MLflow store sqlite:///{junk}: ")


def _serve(answer):
    """A local HTTP server whose GET answers ``answer(path) -> (status, content type, body)``; returns (uri, stop)."""
    import threading
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    class Handler(BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 - http.server's name
            status, kind, body = answer(self.path)
            self.send_response(status)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return f"http://127.0.0.1:{server.server_address[1]}", server.shutdown


def test_a_web_server_that_is_not_mlflow_is_refused_in_one_line(tmp_path, no_retries):
    """Issue 54: any server answering /health passed, and training failed 12 s later in a traceback with HTML. One
    request, no retry (the server counts them)."""
    asked = []

    def answer(path):
        asked.append(path)
        return (200, "text/html", b"<html>OK</html>") if path == "/health" else (404, "text/html", b"<html>no</html>")

    uri, stop = _serve(answer)
    try:
        with pytest.raises(PreflightError) as e:
            check_store(uri)
        assert len(asked) == 1, asked
        assert str(e.value).startswith(f"MLflow store {uri}: answers, but is not an MLflow tracking server (GET ")
        assert "HTTP 404" in str(e.value) and "\n" not in str(e.value)
    finally:
        stop()


@pytest.mark.parametrize(
    "status, body",
    [
        (200, b'{"experiment": {"experiment_id": "0", "name": "Default"}}'),
        (404, b'{"error_code": "RESOURCE_DOES_NOT_EXIST", "message": "no experiment Default"}'),
        (401, b"<html>log in</html>"),  # behind authentication: left to MLflow and its credentials
    ],
)
def test_an_mlflow_server_passes(status, body):
    from emml.runs.preflight import MLFLOW_PROBE

    def answer(path):
        return (status, "application/json", body) if path == MLFLOW_PROBE else (404, "text/html", b"")

    uri, stop = _serve(answer)
    try:
        check_store(uri)
        check_store(uri + "/")
    finally:
        stop()


def test_a_new_store_is_created_once_by_starts_racing_for_it(tmp_path):
    """Issue 54: two launches on a new sqlite store: the second died in MLflow's schema migration
    (`table _alembic_tmp_experiments already exists`). Each start makes it under a lock (`ensure_store`)."""
    import os
    import subprocess
    import sys

    uri = f"sqlite:///{tmp_path}/new/mlflow.db"
    code = "import sys; from emml.runs.preflight import ensure_store; ensure_store(sys.argv[1])"
    procs = [
        subprocess.Popen([sys.executable, "-c", code, uri], stderr=subprocess.PIPE, text=True, env=os.environ.copy())
        for _ in range(3)
    ]
    outs = [(p.wait(timeout=180), p.stderr.read()) for p in procs]
    assert all(rc == 0 for rc, _ in outs), [err[-500:] for _, err in outs]
    with closing(sqlite3.connect(tmp_path / "new" / "mlflow.db")) as con:
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    assert {"alembic_version", "experiments", "runs"} <= tables and not any(
        t.startswith("_alembic_tmp") for t in tables
    )
