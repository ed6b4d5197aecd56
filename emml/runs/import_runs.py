"""Committed run dirs made browsable in the MLflow store (`emml import-runs`, run by `make ui`): each finished run dir
(runs/<table>/<run>/ with results.json and metrics.csv) becomes one FINISHED run of the experiment named by its
table (described by the table's caption), with the tags the trainer sets, its saved config as params, its curve and its
final score (``final/<key>``, apart from the periodic ``eval/<key>`` curve), dated when it trained (`import_run`),
written through MLflow's public API (``MlflowClient.log_batch``, emml/runs/store.py). Its curve: every point of
eval/*, diag/* and final/*, `PER_KEY` points of each per-update key, and the whole metrics.csv as its artifact
(emml/runs/thinning.py: 45 s of CPU for the committed runs instead of 280 s). The params and tags name the
run's roots as this checkout does (``runs``, ``results``: `run_params`) and its files from them (its checkpoint
``runs/<table>/<run>/checkpoint.pt``; a run root outside the checkout by its folder's name, marked as outside:
emml/runs/portable.py, `named`), never a folder of the machine that trained or imported it.

Once and idempotently: a run dir whose run is already in the store (trained here, imported or resumed here before:
`stored_run`, keyed by the MLflow run id the run dir recorded) is skipped, so a second import changes nothing.
An unfinished run dir (no results.json) is skipped: it may be training right now, in this store or another, and
its trainer, resuming here, replays its curve into a run of its own (Tracker.start); importing it as well would
make a second run of it. A finished run dir imported here and then trained further (more frames) resumes its
imported run (`stored_run` in Tracker.start): no second run either.

Under concurrency and interruption too: each run dir is imported under a lock on the store's import
(`import_lock`), taken again for every run dir, so that two imports at once take turns and each finds the run the
other made; the run is created tagged with its run dir (``emml.imported_from``) and ``emml.import_key`` (the run dir
and a digest of its files) and marked done last (``emml.imported_run_id``), so that a run an import killed midway
left behind (RUNNING, not done) is deleted by the next import before it imports that run dir again.

When it trained: results.json's ``started_at`` and ``ended_at``, else estimated from its files and its curve
(emml/runs/import_times.py); the tag ``emml.times`` says which.
"""

from __future__ import annotations

import hashlib
import tempfile
import warnings
from collections.abc import Callable, Iterable, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from emml.config.paths import project_path
from emml.runs import records, store
from emml.runs.diskspace import FULL, RERUN, NoSpaceError
from emml.runs.import_times import commit_times, run_times
from emml.runs.portable import ROOTS, named, root_name
from emml.runs.preflight import ensure_store
from emml.runs.provenance import NOTE, experiment_note
from emml.runs.rundir import CHECKPOINT, FINAL, METRICS, RENAMED, RESULTS, RUN_FILES, RunDirError, read_results
from emml.runs.runlock import holder, waiting_lock
from emml.runs.thinning import PER_KEY, stored_count, thinned
from emml.runs.tracking import IMPORTED_RUN_ID, Tracker, display_name, stored_run

MARKERS = RUN_FILES
"""Files any of which makes a folder a run dir (emml/runs/rundir.py)."""
IMPORTED_FROM = "emml.imported_from"
"""Tag of an imported run: its run dir, named from its run root (`relative`)."""
IMPORT_KEY = "emml.import_key"
"""Tag of a run being imported, set when it is created: its run dir (as `relative` names it) and a digest of its
files (`import_key`). A run with this tag but not ``IMPORTED_RUN_ID`` is an import cut short (SIGTERM, ``kill -9``),
which the next import deletes (`leftover_imports`)."""
TIMES = "emml.times"
"""Tag of an imported run: where its start and end times come from (`run_times`)."""
NOT_TAGS = ("run_name", "run_id", "metrics", "config", "started_at", "ended_at")
"""results.json keys that are not tags: the run name, the id (tag ``IMPORTED_RUN_ID``), the score and config, and
when it trained (the MLflow run's own start and end)."""


@dataclass
class ImportResult:
    """What became of one run dir."""

    run_dir: str
    """The run dir, relative to the project root when under it."""
    outcome: str
    """'imported', 'skipped' or 'failed'."""
    reason: str = ""
    """Why it was skipped or failed."""
    run_id: str | None = None
    """The MLflow run id the run dir recorded (results.json)."""
    mlflow_run_id: str | None = None
    """This store's run of it: the one imported, or the one already here."""
    points: int = 0
    """Metric points stored (one per key and step; per-update keys thinned: emml/runs/thinning.py)."""
    read: int = 0
    """Metric points of the run dir (its metrics.csv, one per key and step, and its final scores)."""

    def line(self) -> str:
        """One line for the terminal."""
        if self.outcome == "imported":
            extra = f" ({self.reason})" if self.reason else ""
            return (
                f"imported {self.run_dir}: MLflow run {self.mlflow_run_id}, {self.points:,} of its {self.read:,} "
                f"metric points{extra}"
            )
        return f"{self.outcome} {self.run_dir}: {self.reason}"


def relative(run_dir: Path) -> str:
    """A run dir as the store names it, on every machine: from the name of its run root (the folder above its table
    folder, as the ``run_root`` param names it: emml.runs.portable.root_name), 'runs/table2/<run>' in a checkout's
    runs/, '<folder> (outside the checkout)/table2/<run>' for a root elsewhere; never '..'."""
    run_dir = Path(run_dir).resolve()
    root = run_dir.parent.parent
    return named(str(run_dir), {str(root): root_name(str(root), ROOTS["run_root"])})


def import_key(run_dir: Path) -> str:
    """The run dir (as `relative` names it) and a digest of its results.json and metrics.csv: tag
    ``emml.import_key`` of its imported run (`IMPORT_KEY`)."""
    digest = hashlib.sha256()
    for name in (RESULTS, METRICS):
        path = Path(run_dir) / name
        if path.is_file():
            digest.update(path.read_bytes())
    return f"{relative(run_dir)}@{digest.hexdigest()[:16]}"


def run_dirs(paths: Iterable[Path]) -> list[Path]:
    """Every run dir (a folder holding results.json, metrics.csv or checkpoint.pt) at or under ``paths``, sorted."""
    found = set()
    for p in map(Path, paths):
        if any((p / m).is_file() for m in MARKERS):
            found.add(p)
        elif p.is_dir():
            found.update(f.parent for m in MARKERS for f in p.rglob(m))
    return sorted(found)


def read_points(path: Path) -> list[tuple[int, str, float]]:
    """A run's metrics.csv as (step, key, value), read by its one reader (`emml.runs.records.read_points`: a torn
    last line left out); any other line that is not a point is a RunDirError naming the file and line."""
    try:
        return records.read_points(path)
    except records.RecordError as e:
        raise RunDirError(str(e)) from None


def run_tags(results: dict, run_dir: Path) -> dict:
    """The tags of an imported run: the trainer's (emml/rl/trainer.py, Trainer.open) where the run dir records them
    (results.json's provenance, the config's tasks, shaping and precision, the checkpoint), and where it came from."""
    tags = {
        RENAMED.get(k, k): v for k, v in results.items() if k not in NOT_TAGS and isinstance(v, (str, int, float, bool))
    }
    config = results.get("config") or {}
    env = config.get("env") or {}
    known = {"tasks": env.get("tasks"), "shaping": env.get("shaping"), "precision": config.get("precision")}
    for key, value in known.items():
        if value is not None:
            tags.setdefault(key, value)
    if (run_dir / CHECKPOINT).is_file():
        tags["checkpoint"] = f"{relative(run_dir)}/{CHECKPOINT}"
    tags[IMPORTED_FROM] = relative(run_dir)
    return tags


def as_trained(value):
    """The saved config as `TrainConfig.to_dict()` gave it (JSON turned its tuples into lists), so that its params
    read as a run trained in this store logs them."""
    if isinstance(value, dict):
        return {k: as_trained(v) for k, v in value.items()}
    if isinstance(value, list):
        return tuple(as_trained(v) for v in value)
    return value


def final_points(results: dict, path: Path) -> list[tuple[int, str, float]]:
    """The run's score (results.json "metrics") as final/<key> at its last frame, as the trainer logs its final
    evaluation: apart from the periodic evaluations' eval/<key> curve (whose last point, in a run dir from before
    final/, is that same evaluation); logged after the curve, it replaces a final/ point the curve has there (a
    score measured again by `emml rescore`, a transfer score the curve lacks)."""
    metrics = results.get("metrics") or {}
    if not isinstance(metrics, dict):
        raise RunDirError(f"{path}: 'metrics' is not an object")
    try:
        frames = int(results.get("frames", 0))
        return [(frames, f"{FINAL}{k}", float(v)) for k, v in metrics.items() if v is not None]
    except (TypeError, ValueError):
        raise RunDirError(f"{path}: 'frames' or a metric is not a number") from None


@contextmanager
def import_lock(uri: str | None = None):
    """Held while one run dir is imported into the store at ``uri``: an exclusive lock (fcntl, released by the kernel
    however the process ends) on a file beside a sqlite store, or in the temporary folder for another store (imports
    on one machine). Two imports at once take turns run dir by run dir, so that each finds the other's runs before
    it would create one."""
    uri = uri or store.tracking_uri()
    db = store.sqlite_path(uri)
    if db is not None:
        db.parent.mkdir(parents=True, exist_ok=True)
        path = db.with_name(db.name + ".import.lock")
    else:
        path = Path(tempfile.gettempdir()) / f"emml-import-{hashlib.sha1(uri.encode()).hexdigest()[:12]}.lock"
    with waiting_lock(path):
        yield


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
    artifacts: Iterable[Path] = (),
) -> str:
    """Log a finished run recorded elsewhere (a run dir's results.json and metrics.csv) as a new FINISHED run of
    ``experiment`` that started at ``start_time`` and ended at ``end_time`` (ms): ``tags``, ``params`` (flattened as
    the tracker logs a config, emml.runs.tracking.flatten), every metric point given (step, key, value), at
    ``when(step)`` (ms), through MLflow's public API (``MlflowClient.log_batch``, emml.runs.store.log_points), and
    the files ``artifacts`` (``MlflowClient.log_artifact``). The
    tag ``IMPORTED_RUN_ID`` = ``run_id``, which marks the import done (`stored_run`), is set last, and a failure on
    the way deletes the half-made run; a run left half-made by a kill is found by the next import (its
    ``IMPORT_KEY`` tag, `leftover_imports`). Data the store refuses (a metric name MLflow does not take) is a
    ValueError. Returns the new run's id."""
    tracker = Tracker(uri)
    try:
        tracker.start(experiment, run_name, tags, params, start_time=start_time)
        log_points(tracker._client, tracker.run_id, list(points), when)
        for path in artifacts:
            tracker.log_artifact(path)
        tracker.set_tags({IMPORTED_RUN_ID: run_id})
        tracker.finish("FINISHED", end_time=end_time)
    except BaseException as e:
        if tracker._run_id is not None:
            _discard(tracker._client, tracker._run_id)
        if getattr(e, "error_code", None) == "INVALID_PARAMETER_VALUE":
            raise ValueError(f"MLflow refused it: {getattr(e, 'message', e)}") from e
        raise
    return tracker.run_id


log_points = store.log_points
"""How an imported run's points are written (a name of this module's: tests stop an import midway through it)."""


def _discard(client, run_id: str) -> None:
    """Delete a half-made run; a store that fails too is warned about (the error that stopped the run matters more)."""
    try:
        store.retry(lambda: client.delete_run(run_id))
    except Exception as e:  # noqa: BLE001
        warnings.warn(f"MLflow run {run_id} could not be deleted: {type(e).__name__}: {e}", stacklevel=3)


def leftover_imports(experiment: str, run_dir: str, uri: str | None = None) -> list[str]:
    """Runs of ``experiment`` imported from ``run_dir`` (tag ``IMPORTED_FROM``) that no import finished (no
    ``IMPORTED_RUN_ID``): a kill (SIGTERM, ``kill -9``) cut their import short. Under `import_lock` none is being
    written."""
    found = store.find_runs(experiment, {IMPORTED_FROM: run_dir}, uri=uri)
    return [r["run_id"] for r in found if IMPORTED_RUN_ID not in r["tags"]]


def set_experiment_note(experiment: str, uri: str | None = None) -> None:
    """Give ``experiment`` its description (emml.runs.provenance.experiment_note) unless it has one (an experiment
    created before descriptions were written, or by another program)."""
    client = store.client(uri)
    exp = store.retry(lambda: client.get_experiment_by_name(experiment))
    if exp is not None and not exp.tags.get(NOTE):
        store.retry(lambda: client.set_experiment_tag(exp.experiment_id, NOTE, experiment_note(experiment)))


def import_run_dir(
    run_dir: Path, uri: str | None = None, committed: dict[Path, float] | None = None, results_root: str = "results"
) -> ImportResult:
    """Import one run dir into the store at ``uri`` (default: tracking_uri()) unless it is unfinished, being
    trained, or already in the store; under the store's import lock, after deleting what an import cut short
    left of it. ``committed``: `commit_times` (read here when None); ``results_root``: `run_params`. RunDirError
    names a file that cannot be read."""
    with import_lock(uri):
        return _import_run_dir(Path(run_dir), uri, committed, results_root)


def run_params(results: dict, run_dir: Path, results_root: str | Path = "results") -> dict:
    """The params of an imported run: its saved config as the trainer logs it (`as_trained`), its roots where they
    are in this checkout (the tracker writes them by name, emml.runs.portable.root_name): ``run_root`` the folder
    that holds the run dir's table folder, ``results_root`` ``results_root`` (a folder of this checkout) when the
    run's own results root was a folder named results/ (on whichever machine), else its own."""
    params = as_trained(results.get("config") or {})
    if "run_root" in params:
        params["run_root"] = str(Path(run_dir).resolve().parent.parent)
    if root_name(str(params.get("results_root")), ROOTS["results_root"]) == ROOTS["results_root"]:
        params["results_root"] = str(project_path(results_root))
    return params


def _import_run_dir(run_dir: Path, uri: str | None, committed: dict[Path, float] | None, results_root) -> ImportResult:
    name = relative(run_dir)
    if not (run_dir / RESULTS).is_file():
        return ImportResult(name, "skipped", f"unfinished (no {RESULTS}): its trainer logs it")
    if (who := holder(run_dir)) is not None:
        return ImportResult(name, "skipped", f"being trained (pid {who.get('pid', '?')} on {who.get('host', '?')})")
    results = read_results(run_dir / RESULTS)
    run_id, experiment = str(results["run_id"]), str(results["table"])
    stored = stored_run(experiment, run_id, uri)
    if stored is not None:
        set_experiment_note(experiment, uri)
        return ImportResult(name, "skipped", f"in the store as MLflow run {stored}", run_id, stored)
    left = leftover_imports(experiment, name, uri)
    if left:  # an import killed midway: its half-made run goes, the run dir is imported whole below
        client = store.client(uri)
        for leftover in left:
            store.retry(lambda leftover=leftover: client.delete_run(leftover))
    curve = read_points(run_dir / METRICS) if (run_dir / METRICS).is_file() else []
    points = curve + final_points(results, run_dir / RESULTS)
    stored = thinned(points, PER_KEY)  # eval/*, diag/*, final/* whole; per-update keys PER_KEY points each
    if committed is None:
        committed = commit_times([run_dir])
    start, end, how, when = run_times(results, run_dir.resolve(), curve, committed)
    tags = {**run_tags(results, run_dir), TIMES: how, IMPORT_KEY: import_key(run_dir)}
    try:
        new = import_run(
            experiment,
            display_name(run_dir, str(results.get("run_name") or run_dir.name)),
            run_id,
            tags,
            run_params(results, run_dir, results_root),
            stored,
            uri,
            start_time=start,
            end_time=end,
            when=when,
            artifacts=[run_dir / METRICS] if (run_dir / METRICS).is_file() else [],  # the whole curve
        )
    except ValueError as e:  # data the store refuses (a metric name it does not take)
        raise RunDirError(f"{run_dir}: {e}") from None
    set_experiment_note(experiment, uri)
    reason = f"removed {len(left)} run(s) an interrupted import left" if left else ""
    return ImportResult(name, "imported", reason, run_id, new, len(stored), len({(k, st) for st, k, _ in points}))


CHECK_DISK = "check the disk (its space, its health) and rerun the same command"
"""What to do after a disk I/O error in the store (a full disk is `RERUN`'s 'free some space')."""
IO_ERROR = "disk I/O error"
"""sqlite's own word for a write its file or journal could not make: a full disk under the journal, a failing
device, a file system gone read-only."""


def write_refused(e: BaseException) -> str | None:
    """Why the store refused a write, if it is the disk's doing: 'no space left on' for an OSError of ENOSPC/EDQUOT
    or sqlite's 'database or disk is full', 'a disk I/O error on' for sqlite's `IO_ERROR`, as SQLAlchemy or MLflow
    wrap them (their message, their cause); None for anything else."""
    for _ in range(10):  # the chain of causes, bounded
        if e is None:
            return None
        if isinstance(e, OSError) and e.errno in FULL or "database or disk is full" in str(e):
            return "no space left on"
        if IO_ERROR in str(e):
            return "a disk I/O error on"
        e = e.__cause__ or e.__context__
    return None


def store_folder(uri: str | None) -> str:
    """The folder of a sqlite store (the one a full disk is about), else the store's URI."""
    uri = uri or store.tracking_uri()
    path = store.sqlite_path(uri)
    return str(path.parent) if path is not None else uri


def import_runs(
    paths: Iterable[Path],
    uri: str | None = None,
    log: Callable[[ImportResult], None] | None = None,
    progress: bool = False,
    results_root: str | Path = "results",
) -> list[ImportResult]:
    """Import every run dir at or under ``paths`` (emml import-runs); a run dir that cannot be read is 'failed'
    (its error named) and the others are imported all the same. ``log`` sees each result as it comes;
    ``progress``: a progress bar with its ETA on stderr (a terminal only) over the points to store (`work`), so that
    a long run dir counts for what it costs, and one skipped or failed takes its share off the total;
    ``results_root``: the folder of this checkout that holds the runs' results rows (`run_params`)."""
    import sys

    from tqdm import tqdm

    dirs = run_dirs(paths)
    ensure_store(uri)  # a new store's tables are made by one process at a time, under the lock the trainer takes too
    committed = commit_times(dirs)
    shown = progress and sys.stderr.isatty()
    weights = {d: work(d) if shown else 1 for d in dirs}
    out = []
    with tqdm(
        total=sum(weights.values()), unit=" pt" if shown else " run", unit_scale=shown, disable=not shown, smoothing=0.1
    ) as bar:
        for run_dir in dirs:
            bar.set_postfix_str(run_dir.name[:40], refresh=False)
            try:
                result = import_run_dir(run_dir, uri, committed, results_root)
            except RunDirError as e:
                result = ImportResult(relative(run_dir), "failed", str(e))
            except Exception as e:
                why = write_refused(e)
                if why is None:
                    raise
                then = RERUN if why.startswith("no space") else CHECK_DISK
                raise NoSpaceError(  # the half-made run was deleted by import_run: the store as it was before it
                    f"{why} {store_folder(uri)} (the MLflow store; importing {relative(run_dir)}, its "
                    f"half-made run removed, the {len(out)} run dirs before it imported whole): {then}"
                ) from None
            if log is not None:
                with bar.external_write_mode():
                    log(result)
            out.append(result)
            if result.outcome == "imported":
                bar.update(weights[run_dir])
            else:  # no work done: off the total, so that the ETA is the imports' left
                bar.total -= weights[run_dir]
                bar.refresh()
    return out


RUN_POINTS = 600
"""What importing a run dir costs beyond its points, in points' time (~0.2 ms of CPU each): its store calls (the
lookups that it is not in the store yet, its run, params, tags, artifact and end), ~0.12 s; measured over the
committed runs (docs/tracking.md)."""
BYTES_PER_POINT = 1800
"""What reading and thinning a metrics.csv costs, in points' time: ~50 of its lines (~36 bytes each) per point
stored, ~4 µs a line."""


def work(run_dir: Path) -> int:
    """A run dir's share of an import's progress bar, in points' time: the points it stores
    (emml.runs.thinning.stored_count), its metrics.csv's reading (`BYTES_PER_POINT`) and `RUN_POINTS`; 0 for one
    without results.json (skipped)."""
    run_dir = Path(run_dir)
    if not (run_dir / RESULTS).is_file():
        return 0
    size = (run_dir / METRICS).stat().st_size if (run_dir / METRICS).is_file() else 0
    return stored_count(run_dir / METRICS) + size // BYTES_PER_POINT + RUN_POINTS
