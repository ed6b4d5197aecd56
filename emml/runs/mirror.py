"""A run's metrics mirror: every metric point the tracker logs, appended to the run dir's metrics.csv
(step,key,value) beside its checkpoint (emml.runs.tracking.Tracker.mirror_to), so that the run dir holds its whole
curve: it resumes in another MLflow store (another machine, a fresh clone) with its curve replayed, and `emml
import-runs` makes a run of it."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from emml.runs import store
from emml.runs.atomic import replacing
from emml.runs.diskspace import RERUN, NoSpaceError, no_space_names
from emml.runs.records import MIRROR_HEADER, read_points


def read_mirror(path: str | os.PathLike | None) -> list[tuple[int, str, float]]:
    """The points of a run's metrics mirror as (step, key, value); [] if absent. A last line cut short by a kill is
    skipped (`emml.runs.records.read_points`, the mirror's one reader)."""
    return [] if path is None else read_points(path)


def append_mirror(path: Path, metrics: Mapping[str, float], step: int) -> None:
    """Append ``metrics`` at ``step`` to the mirror at ``path`` (its header first when new), unbuffered: a full disk
    fails here (NoSpaceError naming the file) and leaves no half line for a resumed run to append to."""
    text = f"{MIRROR_HEADER}\n" if not path.exists() else ""
    text += "".join(f"{int(step)},{k},{float(v)!r}\n" for k, v in metrics.items())
    with open(path, "ab", buffering=0) as f:  # unbuffered: a full disk fails here, not at close
        end, data = f.tell(), memoryview(text.encode())
        try:
            with no_space_names(path):
                while data:
                    data = data[f.write(data) :]
        except NoSpaceError:  # no half line for a resumed run to append to: the file as it was
            f.truncate(end)
            raise


def export_mirror(run_id: str, path: str | os.PathLike, uri: str | None = None) -> int:
    """Write a run's whole curve from the store to a mirror file (for run dirs from before the mirror existed);
    returns the number of points."""
    client = store.client(uri)
    keys = sorted(store.retry(lambda: client.get_run(run_id)).data.metrics)
    points = sorted((st, k, v) for k in keys for st, v in store.metric_history(run_id, k, uri))
    with replacing(path, then=RERUN) as tmp, open(tmp, "w") as f:  # a full disk: one line, the old file kept
        f.write(MIRROR_HEADER + "\n")
        f.writelines(f"{st},{k},{v!r}\n" for st, k, v in points)
    return len(points)
