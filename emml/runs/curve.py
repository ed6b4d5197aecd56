"""A run's evaluation curve, read one way for every page that shows it: a table's curves figure, its sample
efficiency, the claims page's speed and diagnostic claims and its reversals weighed for being settled. Two pages
about the same run read the same points.

The source is decided here, once, per run (never per key, so that one run's curve never mixes two sources):

1. **The run dir's metrics.csv** (its metrics mirror, emml/runs/mirror.py) when it holds a point. The tracker appends
   every point to it before logging the point to MLflow (`Tracker.log_metrics`), so it holds at least what the
   store holds of the run; and it travels with the run dir (committed with the results, copied to another
   machine), so a page reads the same curve on every machine whatever MLflow store that machine has, and a report
   rebuilt from the same commit is the same bytes.
2. **Else the MLflow store's run** (the run id its results row records): a run whose run dir stayed on the machine
   that trained it while its points reached a store read here, or a run from before the mirror (``emml
   import-runs`` and `export_mirror` make a mirror of it).

A metrics.csv that is there but damaged (a line that is not a point) is not passed over for the store: the source
would then turn on a stray line. The run has no curve, its reason says so and a note names the file and the line
(`emml.runs.records.points_or_none`): mend the line, or delete the file to read the store.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from emml.runs import store
from emml.runs.records import points_or_none
from emml.runs.rundir import METRICS

MIRROR = METRICS
"""`RunCurve.source` of a curve read from the run dir's metrics mirror."""
STORE = "mlflow"
"""`RunCurve.source` of a curve read from the MLflow store."""
DAMAGED = "its metrics.csv is damaged (a note names the line)"
"""`RunCurve.reason` when the run dir's metrics.csv is there but holds a line that is not a point."""


@dataclass(frozen=True)
class RunCurve:
    """One run's curves: metric key → frames → value (a point logged twice keeps its last value), from one source."""

    points: Mapping[str, Mapping[int, float]] = field(default_factory=dict)
    """Only the keys asked for that hold a point."""
    source: str = ""
    """Where they were read (`MIRROR` or `STORE`); "" when neither source could be read for the run."""
    reason: str = ""
    """Why there is no point at all ("" when there is one): `DAMAGED`, or what was looked for and not found."""

    @property
    def found(self) -> bool:
        """Whether any key asked for holds a point."""
        return any(self.points.values())

    @property
    def damaged(self) -> bool:
        return self.reason == DAMAGED

    def of(self, key: str) -> list[tuple[int, float]]:
        """The points of ``key`` as (frames, value) in frame order; [] when it has none."""
        return sorted(self.points.get(key, {}).items())


_MIRRORS: dict = {}
"""(path, its size and modification time) → its points by key: a page reads the same runs' files many times (the
claims of one table), each file is parsed once while it is unchanged."""


def _mirror(path: Path) -> dict[str, dict[int, float]] | None:
    """The mirror's points by key ({} when it is absent or holds none), None when it is damaged (noted once)."""
    try:
        stat = path.stat()
    except FileNotFoundError:
        return {}
    key = (path, stat.st_size, stat.st_mtime_ns)
    if key not in _MIRRORS:
        points = points_or_none(path)
        if points is None:
            return None
        by_key: dict[str, dict[int, float]] = {}
        for step, name, value in points:
            by_key.setdefault(name, {})[step] = value
        _MIRRORS[key] = by_key
    return _MIRRORS[key]


def _stored(run_id: str, keys: Iterable[str] | None, uri: str | None) -> dict[str, dict[int, float]] | None:
    """The store's points of run ``run_id`` by key (``keys``, or every key it logged); None when the store does not
    hold the run or cannot be read for it (another machine's database, a store this process cannot open)."""
    try:
        if not store.has_run(run_id, uri):
            return None
        if keys is None:
            client = store.client(uri)
            keys = sorted(store.retry(lambda: client.get_run(run_id)).data.metrics)
        return {k: dict(store.metric_history(run_id, k, uri)) for k in keys}
    except Exception:  # noqa: BLE001 - a store that cannot answer for this run leaves it without a curve, not the page
        return None


def _usable(run_id) -> bool:
    """Whether a results row's run id names a run (an empty or NaN cell does not)."""
    if run_id is None or str(run_id).strip() in ("", "nan", "None"):
        return False
    return not (isinstance(run_id, float) and math.isnan(run_id))


def read_curve(
    folder: str | os.PathLike,
    keys: Iterable[str] | None = None,
    run_id: str | None = None,
    uri: str | None = None,
) -> RunCurve:
    """The curve of the run whose run dir is ``folder`` (it need not be here), by the order of this module: its
    metrics.csv when that holds a point, else MLflow run ``run_id`` of the store at ``uri`` (default: the tracking
    URI), else none with its reason. ``keys``: the metric keys wanted (None: all)."""
    keys = None if keys is None else tuple(dict.fromkeys(keys))
    mirror = _mirror(Path(folder) / METRICS)
    if mirror is None:
        return RunCurve(source=MIRROR, reason=DAMAGED)
    if any(mirror.values()):
        points = _only(mirror, keys)
        return RunCurve(points, MIRROR, "" if points else f"no point of {_keys(keys)} in its metrics.csv")
    stored = _stored(str(run_id), keys, uri) if _usable(run_id) else None
    if stored is None:
        where = f"no MLflow run {run_id} in this store" if _usable(run_id) else "no MLflow run id"
        return RunCurve(reason=f"no metrics.csv here and {where}")
    points = _only(stored, keys)
    return RunCurve(points, STORE, "" if points else f"no point of {_keys(keys)} in MLflow run {run_id}")


def _only(points: Mapping[str, dict[int, float]], keys: tuple[str, ...] | None) -> dict[str, dict[int, float]]:
    """The keys asked for that hold a point (all of them when ``keys`` is None)."""
    wanted = points if keys is None else keys
    return {k: dict(points[k]) for k in wanted if points.get(k)}


def _keys(keys: tuple[str, ...] | None) -> str:
    return "any key" if keys is None else ", ".join(keys) or "no key"
