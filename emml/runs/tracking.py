"""Experiment tracking: the project's only interface to MLflow.

Every other module logs through :class:`Tracker` so that swapping the backend
(local sqlite file, shared ``mlflow server``) is a matter of the
``MLFLOW_TRACKING_URI`` environment variable. ``mlflow`` is imported lazily
inside functions: it takes over a second to import and ``import emml`` must
stay fast.

Conventions (see docs / shared notes on MLflow 3.x):

* Default store is ``sqlite:///<project root>/mlflow.db`` (the plain file store
  is deprecated); artifacts of experiments created here go to
  ``<db dir>/mlartifacts`` rather than the current directory.
* Metrics are logged once per update in one batched call; SQLite "database is
  locked" errors (many concurrent writers) are retried with backoff.
* A run is resumed by passing its ``run_id`` to :meth:`Tracker.start`; steps
  should keep increasing (use the global env-step counter).
* :func:`metric_history` returns full curves (``search_runs`` only keeps the
  latest value per metric).
* A finished run dir from another store becomes a run here with :func:`import_run` (``emml import-runs``,
  emml/runs/import_runs.py); :func:`stored_run` finds a run dir's run here (trained, imported or resumed), so that
  nothing is imported twice and a resumed run dir continues that run.
* What the MLflow UI reads is set as it expects: ``mlflow.source.git.commit`` (and ``mlflow.source.name``) from
  the ``git_sha`` tag (:func:`source_tags`), the experiment's description ``mlflow.note.content`` from its table's
  caption (:func:`experiment_note`), and no absolute path of the machine in a param or tag: a path is written
  relative to the checkout (:func:`portable`).
"""

from __future__ import annotations

import hashlib
import os
import random
import re
import subprocess
import tempfile
import time
import warnings
from collections.abc import Callable, Iterable, Mapping
from contextlib import contextmanager
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any, TypeVar

from emml.config.paths import REPRODUCE_DIR, checkout_root, project_root
from emml.runs.atomic import replacing
from emml.runs.diskspace import RERUN, NoSpaceError, no_space_names
from emml.runs.records import MIRROR_HEADER, read_points
from emml.runs.runlock import waiting_lock

T = TypeVar("T")

_MAX_PARAM_LEN = 6000  # mlflow.utils.validation.MAX_PARAM_VAL_LENGTH
_MAX_TAG_LEN = 8000  # mlflow.utils.validation.MAX_TAG_VAL_LENGTH
_BATCH_PARAMS = 100  # MAX_PARAMS_TAGS_PER_BATCH
_BATCH_METRICS = 1000  # MAX_METRICS_PER_BATCH
_STATUSES = ("FINISHED", "FAILED", "KILLED")
IMPORTED_RUN_ID = "emml.imported_run_id"
"""Tag of a run imported from a finished run dir (:func:`import_run`): the MLflow run id the run dir recorded."""
RESUMED_FROM = "emml.resumed_from_run_id"
"""Tag of a run that resumed a run dir from another store (:meth:`Tracker.start`): the run id the run dir recorded."""
IMPORT_KEY = "emml.import_key"
"""Tag of a run being imported, set when it is created: its run dir (relative to the checkout) and a digest of its
files (emml/runs/import_runs.py, `import_key`). A run with this tag but not ``IMPORTED_RUN_ID`` is an import cut
short (SIGTERM, ``kill -9``), which the next import deletes (:func:`leftover_imports`)."""
NOTE = "mlflow.note.content"
"""The description MLflow's UI shows for an experiment (or a run)."""
GIT_COMMIT = "mlflow.source.git.commit"
"""The commit MLflow's UI shows in a run's Source column (from the ``git_sha`` tag, :func:`source_tags`)."""


def tracking_uri() -> str:
    """``$MLFLOW_TRACKING_URI`` if set, else ``sqlite:///<project root>/mlflow.db``."""
    env = os.environ.get("MLFLOW_TRACKING_URI")
    if env:
        return env
    return f"sqlite:///{project_root() / 'mlflow.db'}"


def _sqlite_path(uri: str) -> Path | None:
    """Filesystem path of a ``sqlite:///`` database (None for other backends / in-memory)."""
    prefix = "sqlite:///"
    if not uri.startswith(prefix):
        return None
    path = uri[len(prefix) :].split("?", 1)[0]
    if not path or path == ":memory:":
        return None
    return Path(path).resolve()


_ABSOLUTE = re.compile(r"(?<![\w.:/~-])/[^\s'\",()\[\]{}]+")
"""An absolute POSIX path inside a value (a path alone, or in a tuple's repr): '/' not after a word, dot, colon
(a URI's 'sqlite:///x' is left alone) or another '/'."""


def portable(value: str) -> str:
    """``value`` with every absolute path in it written relative to the checkout (:func:`checkout_root`): what a
    param or tag may hold, so that the store names no folder of the machine that trained or imported (e.g.
    '/home/me/emml/runs' -> 'runs', '/tmp/x' -> '../../tmp/x' from /home/me/emml)."""
    if "/" not in value:
        return value
    root = str(checkout_root())

    def rel(m: re.Match) -> str:
        path = m.group(0)
        return os.path.relpath(path, root) if os.path.isabs(path) else path

    return _ABSOLUTE.sub(rel, value)


def portable_uri(uri: str) -> str:
    """A tracking URI as a report may print it: a sqlite store's file relative to the checkout
    ('sqlite:////home/me/emml/mlflow.db' -> 'sqlite:///mlflow.db'), any other URI as it is."""
    path = _sqlite_path(uri)
    return f"sqlite:///{portable(str(path))}" if path is not None else uri


_COMMITS: dict[str, str] = {}


def full_commit(sha: str) -> str:
    """The full hash of commit ``sha`` (a run's short ``git_sha``) in the checkout's repository; ``sha`` itself when
    git does not know it (a run trained elsewhere, no git)."""
    if sha in _COMMITS:
        return _COMMITS[sha]
    full = sha
    if re.fullmatch(r"[0-9a-f]{4,40}", sha or ""):
        try:
            out = subprocess.run(
                ["git", "rev-parse", "--verify", "--quiet", f"{sha}^{{commit}}"],
                cwd=project_root(),
                capture_output=True,
                text=True,
                timeout=5,
            )
            full = out.stdout.strip() or sha
        except (OSError, subprocess.SubprocessError):
            pass
    _COMMITS[sha] = full
    return full


def source_tags(tags: Mapping[str, Any]) -> dict[str, str]:
    """The tags MLflow's UI reads for a run's Source, from the run's own ``git_sha`` tag (kept too): its commit (in
    full when this checkout's git knows it) and the program."""
    sha = str(tags.get("git_sha") or "")
    if not sha or sha == "unknown":
        return {}
    return {GIT_COMMIT: full_commit(sha), "mlflow.source.name": "emml", "mlflow.source.type": "LOCAL"}


def experiment_note(name: str) -> str:
    """An experiment's description (``mlflow.note.content``): the caption (``title``) of the table it holds the
    runs of, reproduce/<name>.toml or reproduce/experiments/<name>.toml, with the file; a name no file declares (a
    ``--set table=...`` of one's own) says so."""
    import tomllib

    for path in (REPRODUCE_DIR / f"{name}.toml", REPRODUCE_DIR / "experiments" / f"{name}.toml"):
        if path.is_file():
            try:
                data = tomllib.loads(path.read_text())
            except (OSError, tomllib.TOMLDecodeError):
                break
            title = str(data.get("title") or "").strip() or name
            ref = name if path.parent == REPRODUCE_DIR else f"experiments/{name}"
            return f"{title}\n\nThe runs of `{path.relative_to(REPRODUCE_DIR.parent)}` (`emml run {ref}`)."
    return f"Runs trained with table={name!r}; no table file of reproduce/ declares it."


def _client(uri: str | None = None):
    """MlflowClient for ``uri``; creates the sqlite file's directory if missing."""
    from mlflow import MlflowClient

    uri = uri or tracking_uri()
    db = _sqlite_path(uri)
    if db is not None:
        db.parent.mkdir(parents=True, exist_ok=True)
    return _retry(lambda: MlflowClient(tracking_uri=uri))


def _is_lock_error(exc: BaseException) -> bool:
    text = str(exc).lower()
    return "database is locked" in text or "database table is locked" in text


def _retry(fn: Callable[[], T], attempts: int = 8, base_delay: float = 0.1) -> T:
    """Call ``fn``; retry SQLite lock errors with jittered exponential backoff."""
    for i in range(attempts):
        try:
            return fn()
        except Exception as exc:  # mlflow wraps sqlalchemy errors in MlflowException
            if not _is_lock_error(exc) or i == attempts - 1:
                raise
            time.sleep(base_delay * (2**i) * (0.5 + random.random()))
    raise AssertionError("unreachable")


def flatten(params: Mapping[str, Any] | Any, prefix: str = "") -> dict[str, str]:
    """Flatten nested dicts/dataclasses into ``{"a.b.c": "value"}`` strings."""
    if is_dataclass(params) and not isinstance(params, type):
        params = asdict(params)
    out: dict[str, str] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if is_dataclass(value) and not isinstance(value, type):
            value = asdict(value)
        if isinstance(value, Mapping):
            out.update(flatten(value, prefix=f"{name}."))
        else:
            out[name] = portable(str(value))[:_MAX_PARAM_LEN]
    return out


def tag_strings(tags: Mapping[str, Any]) -> dict[str, str]:
    """Tags as MLflow stores them: strings (cut at its limit) with paths relative to the checkout (:func:`portable`),
    plus the Source tags of a run that names its commit (:func:`source_tags`)."""
    out = {k: portable(str(v))[:_MAX_TAG_LEN] for k, v in tags.items()}
    return {**source_tags(out), **out}


class Tracker:
    """One MLflow run: start (or resume), log metrics/artifacts/tags, finish.

    Usable as a context manager: an exception inside the block finishes the run
    as FAILED, a normal exit as FINISHED.
    """

    def __init__(self, uri: str | None = None) -> None:
        self._uri = uri
        self._client_obj = None
        self._run_id: str | None = None
        self._resume_step: int | None = None
        self._logged: dict[str, set[int]] = {}
        """Per metric key, the steps after ``_resume_step`` that a killed process already logged."""
        self._mirror: Path | None = None
        self._mirrored: set[tuple[str, int]] = set()
        """(key, step) pairs after ``_resume_step`` already in the mirror file."""

    def mirror_to(self, path: str | os.PathLike) -> None:
        """Also append every metric point to ``path`` (CSV: step,key,value), beside the run's checkpoint: the run
        directory then holds its whole curve, so that it can resume in another MLflow store (another machine,
        a fresh clone), which gets the curve replayed (:meth:`start`)."""
        self._mirror = Path(path)

    def resume_after(self, step: int) -> None:
        """The run resumes from a checkpoint at ``step``: points a killed process logged after it are kept and
        the resumed run does not log those (key, step) again, so that every curve has one value per step."""
        self._resume_step, self._logged = step, {}
        self._mirrored = {(k, st) for st, k, _ in read_mirror(self._mirror) if st > step} if self._mirror else set()

    def _already_logged(self, key: str, step: int) -> bool:
        if self._resume_step is None or step <= self._resume_step:
            return False
        if key not in self._logged:  # once per key after a resume
            hist = _retry(lambda: self._client.get_metric_history(self.run_id, key))
            self._logged[key] = {m.step for m in hist if m.step > self._resume_step}
        return step in self._logged[key]

    @property
    def _client(self):
        if self._client_obj is None:
            self._client_obj = _client(self._uri)
        return self._client_obj

    @property
    def run_id(self) -> str:
        if self._run_id is None:
            raise RuntimeError("Tracker.start() has not been called")
        return self._run_id

    def _experiment_id(self, name: str) -> str:
        from mlflow.exceptions import MlflowException

        exp = _retry(lambda: self._client.get_experiment_by_name(name))
        if exp is not None:
            return exp.experiment_id
        db = _sqlite_path(self._uri or tracking_uri())
        artifacts = (db.parent / "mlartifacts").as_uri() if db is not None else None
        try:
            note = {NOTE: experiment_note(name)}
            return _retry(lambda: self._client.create_experiment(name, artifact_location=artifacts, tags=note))
        except MlflowException:
            # Another process created it between our lookup and create.
            exp = _retry(lambda: self._client.get_experiment_by_name(name))
            if exp is None:
                raise
            return exp.experiment_id

    def start(
        self,
        experiment: str,
        run_name: str,
        tags: Mapping[str, Any] | None = None,
        params: Mapping[str, Any] | Any = None,
        run_id: str | None = None,
        parent_run_id: str | None = None,
        start_time: int | None = None,
    ) -> str:
        """Create a run (creating the experiment if missing) or resume ``run_id``, or this store's run of the run dir
        that recorded it (:func:`stored_run`: imported by ``emml import-runs``, or resumed here before).

        ``parent_run_id`` nests the run under a parent (tag ``mlflow.parentRunId``, which MLflow reads across
        processes). On resume, params already logged are left alone; new keys are added and
        keys whose value changed are skipped with a warning (MLflow params are
        immutable). ``start_time`` (ms since the epoch): when the run started, for a run created here that began
        elsewhere (a run dir's record); default now. Returns the run id. A failure once the run exists (its params, a
        replay) ends it FAILED.
        """
        try:
            return self._start(experiment, run_name, tags, params, run_id, parent_run_id, start_time)
        except BaseException as e:  # once created or set RUNNING, the run must not stay RUNNING forever
            self.abort(e)
            raise

    def _start(self, experiment, run_name, tags, params, run_id, parent_run_id, start_time=None) -> str:
        from mlflow.entities import Param

        flat = flatten(params or {})
        if parent_run_id is not None:
            tags = {**(tags or {}), "mlflow.parentRunId": parent_run_id}
        stored = stored_run(experiment, run_id, self._uri) if run_id is not None else None
        if run_id is None:
            exp_id = self._experiment_id(experiment)
            tag_strs = tag_strings(tags or {})
            run = _retry(lambda: self._client.create_run(exp_id, start_time, tag_strs, run_name))
            self._run_id = run.info.run_id
        elif stored is None:  # the run dir came from another store: a new run, its curve replayed
            exp_id = self._experiment_id(experiment)
            tag_strs = tag_strings(tags or {})
            tag_strs[RESUMED_FROM] = run_id
            run = _retry(lambda: self._client.create_run(exp_id, start_time, tag_strs, run_name))
            self._run_id = run.info.run_id
            replayed = self._replay()
            warnings.warn(
                f"MLflow run {run_id} is not in this store ({self._uri or tracking_uri()}): continuing as run "
                f"{self._run_id}, {replayed} metric points replayed from {self._mirror}",
                stacklevel=3,
            )
        else:  # this store's run of the run dir: trained here, or imported (emml import-runs) or resumed before
            run = _retry(lambda: self._client.get_run(stored))
            self._run_id = run.info.run_id
            _retry(lambda: self._client.update_run(stored, status="RUNNING"))
            existing = run.data.params
            changed = sorted(k for k, v in flat.items() if k in existing and existing[k] != v)
            if changed:
                warnings.warn(f"resumed run {stored}: params changed and not re-logged: {changed}", stacklevel=3)
            flat = {k: v for k, v in flat.items() if k not in existing}
            if tags:
                self.set_tags(tags)
        items = [Param(k, v) for k, v in flat.items()]
        for i in range(0, len(items), _BATCH_PARAMS):
            chunk = items[i : i + _BATCH_PARAMS]
            _retry(lambda chunk=chunk: self._client.log_batch(self.run_id, params=chunk))
        return self.run_id

    def has_run(self, run_id: str) -> bool:
        from mlflow.exceptions import MlflowException

        try:
            _retry(lambda: self._client.get_run(run_id))
            return True
        except MlflowException as e:
            if e.error_code == "RESOURCE_DOES_NOT_EXIST":
                return False
            raise

    def export_to_mirror(self, run_id: str) -> int:
        """Fill the mirror file from the store's copy of ``run_id`` (a run dir from before mirrors existed)."""
        return export_mirror(run_id, self._mirror, self._uri)

    def _replay(self) -> int:
        """Log the mirror file's points into the current run (one value per key and step: the last)."""
        if self._mirror is None:
            return 0
        return _log_points(self._client, self.run_id, read_mirror(self._mirror))

    def log_metrics(self, metrics: Mapping[str, float], step: int) -> None:
        """Log all ``metrics`` at ``step`` in one batched call (chunked at MLflow's 1000 limit)."""
        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        if self._mirror is not None:
            fresh = [(k, v) for k, v in metrics.items() if (k, int(step)) not in self._mirrored]
            text = "step,key,value\n" if not self._mirror.exists() else ""
            text += "".join(f"{int(step)},{k},{float(v)!r}\n" for k, v in fresh)
            with open(self._mirror, "ab", buffering=0) as f:  # unbuffered: a full disk fails here, not at close
                end, data = f.tell(), memoryview(text.encode())
                try:
                    with no_space_names(self._mirror):
                        while data:
                            data = data[f.write(data) :]
                except NoSpaceError:  # no half line for a resumed run to append to: the file as it was
                    f.truncate(end)
                    raise
        items = [Metric(k, float(v), now, int(step)) for k, v in metrics.items() if not self._already_logged(k, step)]
        for i in range(0, len(items), _BATCH_METRICS):
            chunk = items[i : i + _BATCH_METRICS]
            _retry(lambda chunk=chunk: self._client.log_batch(self.run_id, metrics=chunk))

    def log_artifact(self, path: str | os.PathLike, artifact_path: str | None = None) -> None:
        """Copy a local file (or directory) into the run's artifact store."""
        _retry(lambda: self._client.log_artifact(self.run_id, str(path), artifact_path))

    def set_tags(self, tags: Mapping[str, Any]) -> None:
        """Set (or overwrite) run tags, e.g. ``{"mlflow.parentRunId": parent}`` for nesting."""
        from mlflow.entities import RunTag

        items = [RunTag(k, v) for k, v in tag_strings(tags).items()]
        for i in range(0, len(items), _BATCH_PARAMS):
            chunk = items[i : i + _BATCH_PARAMS]
            _retry(lambda chunk=chunk: self._client.log_batch(self.run_id, tags=chunk))

    def finish(self, status: str = "FINISHED", end_time: int | None = None) -> None:
        """Mark the run terminated with ``status`` (FINISHED, FAILED or KILLED), at ``end_time`` (ms; default now)."""
        if status not in _STATUSES:
            raise ValueError(f"status must be one of {_STATUSES}, got {status!r}")
        _retry(lambda: self._client.set_terminated(self.run_id, status=status, end_time=end_time))

    def abort(self, exc: BaseException) -> None:
        """End the run after ``exc``, never leaving it RUNNING: KILLED for Ctrl-C or a termination signal
        (SystemExit, emml.envs.engine.install_signal_handlers), else FAILED; nothing if no run was started. A store
        that fails too (the same full disk) is warned about, so that ``exc``, the cause, is what the caller sees."""
        if self._run_id is None:
            return
        try:
            self.finish("KILLED" if isinstance(exc, (KeyboardInterrupt, SystemExit)) else "FAILED")
        except Exception as e:  # noqa: BLE001 - the original error matters more
            warnings.warn(f"MLflow run {self._run_id} could not be marked ended: {type(e).__name__}: {e}", stacklevel=2)

    def __enter__(self) -> Tracker:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._run_id is not None:
            self.finish("FINISHED" if exc_type is None else ("KILLED" if exc_type is KeyboardInterrupt else "FAILED"))


def parent_run(experiment: str, run_name: str, tags: Mapping[str, Any], uri: str | None = None) -> str:
    """The id of the parent run of ``experiment`` tagged ``tags`` (plus ``emml.role=parent``), created if missing.

    Create it before fanning out workers (one writer), then pass its id to each child's ``Tracker.start``.
    A relaunch finds the same parent, so resumed children stay nested under one run.
    """
    tags = {**tags, "emml.role": "parent"}
    found = find_runs(experiment, tags, uri=uri)
    if found:
        return min(found, key=lambda r: r["start_time"])["run_id"]
    tracker = Tracker(uri)
    return tracker.start(experiment, run_name, tags)


def _log_points(
    client, run_id: str, points: Iterable[tuple[int, str, float]], when: Callable[[int], int] | None = None
) -> int:
    """Log (step, key, value) points into ``run_id``, one per key and step (the last), in batches of MLflow's
    limit (``MlflowClient.log_batch``), each point timestamped ``when(step)`` (ms; default now); returns how many
    were logged."""
    from mlflow.entities import Metric

    items = [Metric(k, v, ts, st) for k, st, v, ts in _last_points(points, when)]
    for i in range(0, len(items), _BATCH_METRICS):
        chunk = items[i : i + _BATCH_METRICS]
        _retry(lambda chunk=chunk: client.log_batch(run_id, metrics=chunk))
    return len(items)


def _last_points(points: Iterable[tuple[int, str, float]], when: Callable[[int], int] | None):
    """(key, step, value, timestamp) per key and step (the last value given), by key then step."""
    now = int(time.time() * 1000)
    last = {(k, st): v for st, k, v in points}
    return [(k, st, v, when(st) if when else now) for (k, st), v in sorted(last.items())]


def _bulk_points(client, run_id: str, points, when: Callable[[int], int] | None) -> int | None:
    """Write a new run's points into a sqlite store in one transaction through the installed MLflow's own tables
    (its SqlMetric and SqlLatestMetric models; values as its store sanitizes them, names as its validator checks
    them): 0.3 s for a quick run's 26k points where ``log_batch`` takes 2.5 s of CPU, for the same rows (its ORM
    builds an object per point). None when the store is not sqlite or this MLflow lacks what it uses: then the
    caller logs them with ``log_batch``. A name MLflow refuses is its MlflowException, as from ``log_batch``."""
    store = getattr(getattr(client, "_tracking_client", None), "store", None)
    engine = getattr(store, "engine", None)
    if engine is None or engine.dialect.name != "sqlite" or not hasattr(store, "sanitize_metric_value"):
        return None
    try:
        from mlflow.store.tracking.dbmodels.models import SqlLatestMetric, SqlMetric
        from mlflow.utils.validation import _validate_metric
    except ImportError:
        return None
    columns = ("run_uuid", "key", "value", "timestamp", "step", "is_nan")
    rows, latest = [], {}
    for k, st, v, ts in _last_points(points, when):
        if k not in latest:
            _validate_metric(k, v, ts, st)
        is_nan, value = store.sanitize_metric_value(v)
        row = (run_id, k, value, ts, st, is_nan)
        rows.append(row)
        latest[k] = row  # by key then step: the last row of a key is its latest (MLflow: max step, then time)

    def insert(table) -> str:  # the driver's executemany over tuples: SQLAlchemy's per-row processing costs as much
        missing = [c for c in columns if c not in table.columns]
        missing += [c.name for c in table.columns if c.name not in columns and not (c.nullable or c.default)]
        if missing:  # another MLflow's schema: log_batch
            raise ImportError(f"{table.name}: {missing}")
        return f"INSERT INTO {table.name} ({', '.join(columns)}) VALUES ({', '.join('?' * len(columns))})"

    try:
        sql = insert(SqlMetric.__table__), insert(SqlLatestMetric.__table__)
    except ImportError:
        return None

    def write() -> None:
        with engine.begin() as conn:
            conn.exec_driver_sql(sql[0], rows)
            conn.exec_driver_sql(sql[1], list(latest.values()))

    if rows:
        _retry(write)
    return len(rows)


@contextmanager
def import_lock(uri: str | None = None):
    """Held while one run dir is imported into the store at ``uri`` (emml/runs/import_runs.py): an exclusive lock
    (fcntl, released by the kernel however the process ends) on a file beside a sqlite store, or in the temporary
    folder for another store (imports on one machine). Two imports at once take turns run dir by run dir, so that
    each finds the other's runs before it would create one."""
    uri = uri or tracking_uri()
    db = _sqlite_path(uri)
    if db is not None:
        db.parent.mkdir(parents=True, exist_ok=True)
        path = db.with_name(db.name + ".import.lock")
    else:
        path = Path(tempfile.gettempdir()) / f"emml-import-{hashlib.sha1(uri.encode()).hexdigest()[:12]}.lock"
    with waiting_lock(path):
        yield


def stored_run(experiment: str, run_id: str, uri: str | None = None) -> str | None:
    """This store's run of the run dir that recorded MLflow run ``run_id``: that run when it is here (trained here),
    else the run of ``experiment`` imported from the run dir (tag ``IMPORTED_RUN_ID``) or resuming it (tag
    ``RESUMED_FROM``), the earliest if several; None when the store has none."""
    if Tracker(uri).has_run(run_id):
        return run_id
    for tag in (IMPORTED_RUN_ID, RESUMED_FROM):
        found = find_runs(experiment, {tag: run_id}, uri=uri)
        if found:
            return min(found, key=lambda r: r["start_time"])["run_id"]
    return None


def import_run(
    experiment: str,
    run_name: str,
    run_id: str,
    tags: Mapping[str, Any],
    params: Mapping[str, Any],
    points: Iterable[tuple[int, str, float]],
    uri: str | None = None,
    start_time: int | None = None,
    end_time: int | None = None,
    when: Callable[[int], int] | None = None,
    bulk: bool = True,
) -> str:
    """Log a finished run recorded elsewhere (a run dir's results.json and metrics.csv, emml/runs/import_runs.py) as a
    new FINISHED run of ``experiment`` that started at ``start_time`` and ended at ``end_time`` (ms): ``tags``,
    ``params`` (flattened as :meth:`Tracker.start` logs a config) and every metric point (step, key, value), at
    ``when(step)`` (ms). The tag ``IMPORTED_RUN_ID`` = ``run_id``, which marks the import done
    (:func:`stored_run`), is set last, and a failure on the way deletes the half-made run; a run left half-made by a
    kill is found by the next import (its ``IMPORT_KEY`` tag, :func:`leftover_imports`). ``bulk``: a sqlite store's
    points in one transaction (:func:`_bulk_points`), else ``log_batch``. Data the store refuses (a metric name
    MLflow does not take) is a ValueError. Returns the new run's id."""
    tracker = Tracker(uri)
    try:
        tracker.start(experiment, run_name, tags, params, start_time=start_time)
        points = list(points)
        done = _bulk_points(tracker._client, tracker.run_id, points, when) if bulk else None
        if done is None:
            _log_points(tracker._client, tracker.run_id, points, when)
        tracker.set_tags({IMPORTED_RUN_ID: run_id})
        tracker.finish("FINISHED", end_time=end_time)
    except BaseException as e:
        if tracker._run_id is not None:
            _discard(tracker._client, tracker._run_id)
        if getattr(e, "error_code", None) == "INVALID_PARAMETER_VALUE":
            raise ValueError(f"MLflow refused it: {getattr(e, 'message', e)}") from e
        raise
    return tracker.run_id


def leftover_imports(experiment: str, key_tag: str, key: str, uri: str | None = None) -> list[str]:
    """Runs of ``experiment`` whose tag ``key_tag`` is ``key`` that no import finished (no ``IMPORTED_RUN_ID``): a
    kill (SIGTERM, ``kill -9``) cut their import short. Under :func:`import_lock` none is being written."""
    return [r["run_id"] for r in find_runs(experiment, {key_tag: key}, uri=uri) if IMPORTED_RUN_ID not in r["tags"]]


def delete_runs(run_ids: Iterable[str], uri: str | None = None) -> None:
    """Delete runs (an import's leftovers)."""
    client = _client(uri)
    for run_id in run_ids:
        _retry(lambda run_id=run_id: client.delete_run(run_id))


def set_experiment_note(experiment: str, uri: str | None = None) -> None:
    """Give ``experiment`` its description (:func:`experiment_note`) unless it has one (an experiment created before
    descriptions were written, or by another program)."""
    client = _client(uri)
    exp = _retry(lambda: client.get_experiment_by_name(experiment))
    if exp is not None and not exp.tags.get(NOTE):
        _retry(lambda: client.set_experiment_tag(exp.experiment_id, NOTE, experiment_note(experiment)))


def _discard(client, run_id: str) -> None:
    """Delete a half-made run; a store that fails too is warned about (the error that stopped the run matters more)."""
    try:
        _retry(lambda: client.delete_run(run_id))
    except Exception as e:  # noqa: BLE001
        warnings.warn(f"MLflow run {run_id} could not be deleted: {type(e).__name__}: {e}", stacklevel=3)


def set_run_status(run_id: str, status: str, uri: str | None = None) -> None:
    """Mark a run (e.g. a parent run once its children are done) FINISHED, FAILED, KILLED or RUNNING."""
    if status not in (*_STATUSES, "RUNNING"):
        raise ValueError(f"status must be one of {(*_STATUSES, 'RUNNING')}, got {status!r}")
    client = _client(uri)
    if status == "RUNNING":
        _retry(lambda: client.update_run(run_id, status="RUNNING"))
    else:
        _retry(lambda: client.set_terminated(run_id, status=status))


def read_mirror(path: str | os.PathLike | None) -> list[tuple[int, str, float]]:
    """The points of a run's metrics mirror (:meth:`Tracker.mirror_to`) as (step, key, value); [] if absent.
    A last line cut short by a kill is skipped (`emml.runs.records.read_points`, the mirror's one reader)."""
    return [] if path is None else read_points(path)


def export_mirror(run_id: str, path: str | os.PathLike, uri: str | None = None) -> int:
    """Write a run's whole curve from the store to a mirror file (for run dirs from before the mirror existed);
    returns the number of points."""
    client = _client(uri)
    keys = sorted(_retry(lambda: client.get_run(run_id)).data.metrics)
    points = sorted((st, k, v) for k in keys for st, v in metric_history(run_id, k, uri))
    with replacing(path, then=RERUN) as tmp, open(tmp, "w") as f:  # a full disk: one line, the old file kept
        f.write(MIRROR_HEADER + "\n")
        f.writelines(f"{st},{k},{v!r}\n" for st, k, v in points)
    return len(points)


def metric_history(run_id: str, key: str, uri: str | None = None) -> list[tuple[int, float]]:
    """Full curve of metric ``key`` as ``[(step, value), ...]`` sorted by step (then time)."""
    client = _client(uri)
    hist = _retry(lambda: client.get_metric_history(run_id, key))
    return [(m.step, m.value) for m in sorted(hist, key=lambda m: (m.step, m.timestamp))]


def _quote(value: Any) -> str:
    return "'" + str(value).replace("\\", "\\\\").replace("'", "\\'") + "'"


def find_runs(experiment: str, filter_tags: Mapping[str, Any] | None = None, uri: str | None = None) -> list[dict]:
    """Runs of ``experiment`` whose tags equal ``filter_tags`` (all pages).

    Each run is a dict: ``run_id``, ``run_name``, ``status``, ``start_time``
    (ms), ``tags``, ``params`` and ``metrics`` (latest value of each). Missing
    experiment -> empty list.
    """
    client = _client(uri)
    exp = _retry(lambda: client.get_experiment_by_name(experiment))
    if exp is None:
        return []
    filt = " and ".join(f"tags.`{k}` = {_quote(v)}" for k, v in (filter_tags or {}).items())
    runs: list[dict] = []
    token = None
    while True:
        page = _retry(lambda token=token: client.search_runs([exp.experiment_id], filter_string=filt, page_token=token))
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
