"""Committed run dirs made browsable in the MLflow store (`emml import-runs`, run by `make ui`): each finished run dir
(runs/<table>/<run>/ with results.json and metrics.csv) becomes one FINISHED run of the experiment named by its
table, with the tags the trainer sets, its saved config as params, its whole curve and its final score
(emml/runs/tracking.py, `import_run`).

Once and idempotently: a run dir whose run is already in the store (trained here, imported or resumed here before:
`stored_run`, keyed by the MLflow run id the run dir recorded) is skipped, so a second import changes nothing.
An unfinished run dir (no results.json) is skipped: it may be training right now, in this store or another, and
its trainer, resuming here, replays its curve into a run of its own (Tracker.start); importing it as well would
make a second run of it. A finished run dir imported here and then trained further (more frames) resumes its
imported run (`stored_run` in Tracker.start): no second run either.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from emml.runs.rundir import CHECKPOINT, METRICS, RESULTS, RUN_FILES, RunDirError, read_results

MARKERS = RUN_FILES
"""Files any of which makes a folder a run dir (emml/runs/rundir.py)."""
HEADER = "step,key,value"
IMPORTED_FROM = "emml.imported_from"
"""Tag of an imported run: its run dir, relative to the project root when under it."""
NOT_TAGS = ("run_name", "run_id", "metrics", "config")
"""results.json keys that are not tags: the run name, the id (tag ``IMPORTED_RUN_ID``), the score and config."""


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
    """Metric points imported (one per key and step)."""

    def line(self) -> str:
        """One line for the terminal."""
        if self.outcome == "imported":
            return f"imported {self.run_dir}: MLflow run {self.mlflow_run_id}, {self.points:,} metric points"
        return f"{self.outcome} {self.run_dir}: {self.reason}"


def relative(path: Path) -> str:
    """``path`` relative to the project root when under it, else absolute."""
    from emml.config.paths import project_root

    path = Path(path).resolve()
    try:
        return str(path.relative_to(project_root()))
    except ValueError:
        return str(path)


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
    """A run's metrics.csv (step,key,value; emml.runs.tracking.Tracker.mirror_to) as (step, key, value), strictly: a
    wrong header or a line that is not step,key,value is a RunDirError naming the file and line."""
    lines = Path(path).read_text().splitlines()
    if not lines or lines[0] != HEADER:
        raise RunDirError(f"{path}:1: header {lines[0] if lines else ''!r} is not {HEADER!r}")
    out = []
    for number, line in enumerate(lines[1:], start=2):
        try:
            step, rest = line.split(",", 1)
            key, value = rest.rsplit(",", 1)
            if not key:
                raise ValueError
            out.append((int(step), key, float(value)))
        except ValueError:
            raise RunDirError(f"{path}:{number}: not a step,key,value line: {line[:80]!r}") from None
    return out


def run_tags(results: dict, run_dir: Path) -> dict:
    """The tags of an imported run: the trainer's (emml/rl/trainer.py, Trainer.open) where the run dir records them
    (results.json's provenance, the config's tasks, shaping and precision, the checkpoint), and where it came from."""
    tags = {k: v for k, v in results.items() if k not in NOT_TAGS and isinstance(v, (str, int, float, bool))}
    config = results.get("config") or {}
    env = config.get("env") or {}
    known = {"tasks": env.get("tasks"), "shaping": env.get("shaping"), "precision": config.get("precision")}
    for key, value in known.items():
        if value is not None:
            tags.setdefault(key, value)
    if (run_dir / CHECKPOINT).is_file():
        tags["checkpoint"] = str(run_dir.resolve() / CHECKPOINT)
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
    """The run's score (results.json "metrics") as eval/<key> at its last frame, as the trainer logs its final
    evaluation; logged after the curve, it replaces the curve's point there (a score measured again by `emml
    rescore`, a transfer score the curve lacks)."""
    metrics = results.get("metrics") or {}
    if not isinstance(metrics, dict):
        raise RunDirError(f"{path}: 'metrics' is not an object")
    try:
        frames = int(results.get("frames", 0))
        return [(frames, f"eval/{k}", float(v)) for k, v in metrics.items() if v is not None]
    except (TypeError, ValueError):
        raise RunDirError(f"{path}: 'frames' or a metric is not a number") from None


def import_run_dir(run_dir: Path, uri: str | None = None) -> ImportResult:
    """Import one run dir into the store at ``uri`` (default: tracking_uri()) unless it is unfinished, being
    trained, or already in the store. RunDirError names a file that cannot be read."""
    from emml.runs.runlock import holder
    from emml.runs.tracking import import_run, stored_run

    run_dir = Path(run_dir)
    name = relative(run_dir)
    if not (run_dir / RESULTS).is_file():
        return ImportResult(name, "skipped", f"unfinished (no {RESULTS}): its trainer logs it")
    if (who := holder(run_dir)) is not None:
        return ImportResult(name, "skipped", f"being trained (pid {who.get('pid', '?')} on {who.get('host', '?')})")
    results = read_results(run_dir / RESULTS)
    run_id, experiment = str(results["run_id"]), str(results["table"])
    stored = stored_run(experiment, run_id, uri)
    if stored is not None:
        return ImportResult(name, "skipped", f"in the store as MLflow run {stored}", run_id, stored)
    curve = read_points(run_dir / METRICS) if (run_dir / METRICS).is_file() else []
    points = curve + final_points(results, run_dir / RESULTS)
    try:
        new = import_run(
            experiment,
            str(results.get("run_name") or run_dir.name),
            run_id,
            run_tags(results, run_dir),
            as_trained(results.get("config") or {}),
            points,
            uri,
        )
    except ValueError as e:  # data the store refuses (a metric name it does not take)
        raise RunDirError(f"{run_dir}: {e}") from None
    return ImportResult(name, "imported", "", run_id, new, len({(k, st) for st, k, _ in points}))


def import_runs(
    paths: Iterable[Path], uri: str | None = None, log: Callable[[ImportResult], None] | None = None
) -> list[ImportResult]:
    """Import every run dir at or under ``paths`` (emml import-runs); a run dir that cannot be read is 'failed'
    (its error named) and the others are imported all the same. ``log`` sees each result as it comes."""
    out = []
    for run_dir in run_dirs(paths):
        try:
            result = import_run_dir(run_dir, uri)
        except RunDirError as e:
            result = ImportResult(relative(run_dir), "failed", str(e))
        if log is not None:
            log(result)
        out.append(result)
    return out
