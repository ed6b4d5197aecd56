"""Experiment tracking: a run's MLflow run, the project's only writer of the runs it trains (emml/runs/store.py is
how the store is reached, through MLflow's public API).

Every other module logs through :class:`Tracker`, so that swapping the backend (local sqlite file, shared ``mlflow
server``) is a matter of the ``MLFLOW_TRACKING_URI`` environment variable.

* Metrics are logged once per update in one batched call, mirrored to the run dir's metrics.csv
  (emml/runs/mirror.py).
* A run is resumed by passing its ``run_id`` to :meth:`Tracker.start`; steps should keep increasing (use the global
  env-step counter). :func:`stored_run` finds a run dir's run in this store (trained, imported by ``emml
  import-runs`` (emml/runs/import_runs.py, which owns the import) or resumed here), so that nothing is imported twice
  and a resumed run dir continues that run.
* What the MLflow UI reads is set as it expects (emml/runs/provenance.py), and no path of the machine is in a param
  or tag: a run's roots by their names, a path under them from that name, another relative to the checkout
  (emml/runs/portable.py, `named`).
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Mapping
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any

from emml.config.paths import checkout_root
from emml.envs.stops import note_stop
from emml.runs import pending_ends, store
from emml.runs.mirror import append_mirror, export_mirror, read_mirror
from emml.runs.portable import ROOTS, named, root_name, run_roots
from emml.runs.provenance import NOTE, experiment_note, source_tags
from emml.runs.store import MAX_PARAM_LEN, MAX_TAG_LEN, StoreGaveUp, retry

__all__ = ["Tracker", "display_name", "flatten", "parent_run", "set_run_status", "stored_run", "tag_strings"]

STATUSES = ("FINISHED", "FAILED", "KILLED")
IMPORTED_RUN_ID = "emml.imported_run_id"
"""Tag of a run imported from a finished run dir (emml/runs/import_runs.py): the MLflow run id the run dir
recorded; set last, it marks the import done (`stored_run` finds the run by it)."""
RESUMED_FROM = "emml.resumed_from_run_id"
"""Tag of a run that resumed a run dir from another store (:meth:`Tracker.start`): the run id the run dir recorded."""
DEFAULT_ROOT = ROOTS["run_root"]
"""The run root whose run dirs are named by their run name alone in the store (`display_name`)."""


def flatten(
    params: Mapping[str, Any] | Any, prefix: str = "", roots: Mapping[str, str] | None = None
) -> dict[str, str]:
    """Flatten nested dicts/dataclasses into ``{"a.b.c": "value"}`` strings, as a param may hold them: the run's
    roots (``run_root``, ``results_root``) by their names (``runs``, `root_name`), every other path as the store
    names it (`named`: under a root from its name, else relative to the checkout; ``roots``: `run_roots`, default
    the params' own), cut at MLflow's limit."""
    if is_dataclass(params) and not isinstance(params, type):
        params = asdict(params)
    if roots is None:
        roots = run_roots(params)
    out: dict[str, str] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if is_dataclass(value) and not isinstance(value, type):
            value = asdict(value)
        if isinstance(value, Mapping):
            out.update(flatten(value, prefix=f"{name}.", roots=roots))
        else:
            text = root_name(str(value), ROOTS[name]) if name in ROOTS else named(str(value), roots)
            out[name] = text[:MAX_PARAM_LEN]
    return out


def tag_strings(tags: Mapping[str, Any], roots: Mapping[str, str] | None = None) -> dict[str, str]:
    """Tags as MLflow stores them: strings (cut at its limit) with every path as the store names it (`named`: under
    one of the run's ``roots`` (`run_roots`) from that root's name, e.g. the checkpoint 'runs/table2/<run>/
    checkpoint.pt', else relative to the checkout, never '..'), plus the Source tags of a run that names its commit
    (:func:`source_tags`)."""
    out = {k: named(str(v), roots)[:MAX_TAG_LEN] for k, v in tags.items()}
    return {**source_tags(out), **out}


def display_name(run_dir: Path, name: str) -> str:
    """A run's name in the store, unique in its experiment for the run dirs of a checkout: its run name, followed by
    its run root when that is not a folder named runs/: a root inside the checkout's runs/ by its path from there
    (``dual_attention-easy-aux-s1-quick [extended]`` for runs/extended/table2, beside the run of the same name in
    runs/table2), another by its folder's name (never a path of the machine)."""
    root = Path(run_dir).resolve().parent.parent
    if root.name == DEFAULT_ROOT and root.parent.resolve() != (checkout_root() / DEFAULT_ROOT).resolve():
        return name
    try:
        return f"{name} [{root.relative_to((checkout_root() / DEFAULT_ROOT).resolve())}]"
    except ValueError:
        return f"{name} [{root.name}]"


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
        self._roots: dict[str, str] = {}
        """The run's roots (its config's ``run_root``, ``results_root``: `run_roots`) by which its tags name paths."""

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
            hist = retry(lambda: self._client.get_metric_history(self.run_id, key))
            self._logged[key] = {m.step for m in hist if m.step > self._resume_step}
        return step in self._logged[key]

    @property
    def _client(self):
        if self._client_obj is None:
            self._client_obj = store.client(self._uri)
        return self._client_obj

    @property
    def run_id(self) -> str:
        if self._run_id is None:
            raise RuntimeError("Tracker.start() has not been called")
        return self._run_id

    def _experiment_id(self, name: str) -> str:
        from mlflow.exceptions import MlflowException

        exp = retry(lambda: self._client.get_experiment_by_name(name))
        if exp is not None:
            return exp.experiment_id
        db = store.sqlite_path(self._uri or store.tracking_uri())
        artifacts = (db.parent / "mlartifacts").as_uri() if db is not None else None
        try:
            note = {NOTE: experiment_note(name)}
            return retry(lambda: self._client.create_experiment(name, artifact_location=artifacts, tags=note))
        except MlflowException:
            # Another process created it between our lookup and create.
            exp = retry(lambda: self._client.get_experiment_by_name(name))
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
        self._apply_pending_ends()
        try:
            return self._start(experiment, run_name, tags, params, run_id, parent_run_id, start_time)
        except BaseException as e:  # once created or set RUNNING, the run must not stay RUNNING forever
            self.abort(e)
            raise

    def _start(self, experiment, run_name, tags, params, run_id, parent_run_id, start_time=None) -> str:
        from mlflow.entities import Param

        raw = asdict(params) if is_dataclass(params) and not isinstance(params, type) else (params or {})
        self._roots = run_roots(raw)
        flat = flatten(raw, roots=self._roots)
        if parent_run_id is not None:
            tags = {**(tags or {}), "mlflow.parentRunId": parent_run_id}
        stored = stored_run(experiment, run_id, self._uri) if run_id is not None else None
        if run_id is None:
            exp_id = self._experiment_id(experiment)
            tag_strs = tag_strings(tags or {}, self._roots)
            run = retry(lambda: self._client.create_run(exp_id, start_time, tag_strs, run_name))
            self._run_id = run.info.run_id
        elif stored is None:  # the run dir came from another store: a new run, its curve replayed
            exp_id = self._experiment_id(experiment)
            tag_strs = tag_strings(tags or {}, self._roots)
            tag_strs[RESUMED_FROM] = run_id
            run = retry(lambda: self._client.create_run(exp_id, start_time, tag_strs, run_name))
            self._run_id = run.info.run_id
            replayed = self._replay()
            warnings.warn(
                f"MLflow run {run_id} is not in this store ({self._uri or store.tracking_uri()}): continuing as run "
                f"{self._run_id}, {replayed} metric points replayed from {self._mirror}",
                stacklevel=3,
            )
        else:  # this store's run of the run dir: trained here, or imported (emml import-runs) or resumed before
            run = retry(lambda: self._client.get_run(stored))
            self._run_id = run.info.run_id
            pending_ends.drop_end(self._uri, stored)  # resumed: its status is set here, not by a record of its stop
            retry(lambda: self._client.update_run(stored, status="RUNNING"))
            existing = run.data.params
            changed = sorted(k for k, v in flat.items() if k in existing and existing[k] != v)
            if changed:
                warnings.warn(f"resumed run {stored}: params changed and not re-logged: {changed}", stacklevel=3)
            flat = {k: v for k, v in flat.items() if k not in existing}
            if tags:
                self.set_tags(tags)
        store.log_batch(self._client, self.run_id, params=[Param(k, v) for k, v in flat.items()])
        return self.run_id

    def _apply_pending_ends(self) -> None:
        """Write the ends recorded by processes that stopped while this store was locked (`pending_ends.apply_ends`);
        a store that fails here is warned about, and the start goes on (it meets the same store next)."""
        try:
            pending_ends.apply_ends(self._uri, self._client)
        except Exception as e:  # noqa: BLE001 - a start is not refused over another run's status
            warnings.warn(f"pending MLflow run ends not written: {type(e).__name__}: {e}", stacklevel=3)

    def has_run(self, run_id: str) -> bool:
        """Whether this store holds run ``run_id``."""
        return store.has_run(run_id, mlflow_client=self._client)

    def export_to_mirror(self, run_id: str) -> int:
        """Fill the mirror file from the store's copy of ``run_id`` (a run dir from before mirrors existed)."""
        return export_mirror(run_id, self._mirror, self._uri)

    def _replay(self) -> int:
        """Log the mirror file's points into the current run (one value per key and step: the last)."""
        if self._mirror is None:
            return 0
        return store.log_points(self._client, self.run_id, read_mirror(self._mirror))

    def log_metrics(self, metrics: Mapping[str, float], step: int) -> None:
        """Log all ``metrics`` at ``step`` in one batched call (chunked at MLflow's 1000 limit)."""
        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        if self._mirror is not None:
            fresh = {k: v for k, v in metrics.items() if (k, int(step)) not in self._mirrored}
            append_mirror(self._mirror, fresh, step)
        items = [Metric(k, float(v), now, int(step)) for k, v in metrics.items() if not self._already_logged(k, step)]
        store.log_batch(self._client, self.run_id, metrics=items)

    def log_artifact(self, path: str | os.PathLike, artifact_path: str | None = None) -> None:
        """Copy a local file (or directory) into the run's artifact store."""
        retry(lambda: self._client.log_artifact(self.run_id, str(path), artifact_path))

    def set_tags(self, tags: Mapping[str, Any]) -> None:
        """Set (or overwrite) run tags, e.g. ``{"mlflow.parentRunId": parent}`` for nesting."""
        from mlflow.entities import RunTag

        strings = tag_strings(tags, self._roots)
        store.log_batch(self._client, self.run_id, tags=[RunTag(k, v) for k, v in strings.items()])

    def finish(self, status: str = "FINISHED", end_time: int | None = None) -> None:
        """Mark the run terminated with ``status`` (FINISHED, FAILED or KILLED), at ``end_time`` (ms; default now)."""
        if status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {status!r}")
        end_time = end_time if end_time is not None else int(time.time() * 1000)
        try:
            retry(lambda: self._client.set_terminated(self.run_id, status=status, end_time=end_time))
        except StoreGaveUp:  # a stopping process and a locked store: the next start writes it (pending_ends)
            run_dir = self._mirror.parent if self._mirror is not None else None
            pending_ends.record_end(self._uri, self.run_id, status, end_time, run_dir)
            raise

    def abort(self, exc: BaseException) -> None:
        """End the run after ``exc``, never leaving it RUNNING: KILLED for Ctrl-C or a termination signal
        (SystemExit, emml.envs.engine.install_signal_handlers), else FAILED; nothing if no run was started. A store
        that fails too (the same full disk) is warned about, so that ``exc``, the cause, is what the caller sees; a
        store that does not answer within seconds of a stop is given up, the run's end recorded for the next start
        (emml/runs/pending_ends.py)."""
        stopped = isinstance(exc, (KeyboardInterrupt, SystemExit))
        if stopped:
            note_stop()  # the store gets seconds, not minutes, from now (emml/runs/store.py, STOP_GRACE_S)
        if self._run_id is None:
            return
        try:
            self.finish("KILLED" if stopped else "FAILED")
        except StoreGaveUp as e:
            warnings.warn(
                f"MLflow run {self._run_id} left RUNNING: {e}; it is marked {'KILLED' if stopped else 'FAILED'} at "
                "the next start against this store",
                stacklevel=2,
            )
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
    found = store.find_runs(experiment, tags, uri=uri)
    if found:
        return min(found, key=lambda r: r["start_time"])["run_id"]
    tracker = Tracker(uri)
    return tracker.start(experiment, run_name, tags)


def stored_run(experiment: str, run_id: str, uri: str | None = None) -> str | None:
    """This store's run of the run dir that recorded MLflow run ``run_id``: that run when it is here (trained here),
    else the run of ``experiment`` imported from the run dir (tag ``IMPORTED_RUN_ID``) or resuming it (tag
    ``RESUMED_FROM``), the earliest if several; None when the store has none."""
    if store.has_run(run_id, uri):
        return run_id
    for tag in (IMPORTED_RUN_ID, RESUMED_FROM):
        found = store.find_runs(experiment, {tag: run_id}, uri=uri)
        if found:
            return min(found, key=lambda r: r["start_time"])["run_id"]
    return None


def set_run_status(run_id: str, status: str, uri: str | None = None) -> None:
    """Mark a run (e.g. a parent run once its children are done) FINISHED, FAILED, KILLED or RUNNING."""
    if status not in (*STATUSES, "RUNNING"):
        raise ValueError(f"status must be one of {(*STATUSES, 'RUNNING')}, got {status!r}")
    client = store.client(uri)
    if status == "RUNNING":
        retry(lambda: client.update_run(run_id, status="RUNNING"))
    else:
        retry(lambda: client.set_terminated(run_id, status=status))
