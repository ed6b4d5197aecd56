"""Which of a run dir's metric points its imported MLflow run stores (`emml import-runs`, emml/runs/import_runs.py).

A run dir's metrics.csv holds ~20 keys logged at every PPO update (losses/*, charts/*, train/*, perf/*: 1,000 to
10,000 points each, 1.6 M in the committed runs) and a few logged at each periodic evaluation (eval/*, diag/*,
perf/eval_s: tens of points). Every point written through MLflow's API costs ~0.2 ms of CPU (its ORM builds an
object per point): 1.6 M points were 280 s of CPU; the import must be a minute's wait. So an imported run stores:

* every point of the keys the reports and the claims read (`WHOLE`: eval/*, diag/*, final/*), and of any key with
  at most `PER_KEY` points;
* `PER_KEY` points of every other key (a per-update curve), evenly spaced over its steps, its first and last
  included, each a value the run logged (no averaging: a point in the store is one the trainer wrote);
* the whole metrics.csv beside them as the run's artifact (``metrics.csv``, emml.runs.import_runs.import_run), so
  that nothing is lost: every point of every key is one click away in the UI, and in the run dir.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Iterable
from pathlib import Path

WHOLE = ("eval/", "diag/", "final/")
"""Key prefixes stored whole: the periodic greedy evaluations (the tables' curves, emml/report/curves.py, and their
crossings, emml/report/efficiency.py), the diagnostics the claims page reads (emml/report/claims.py) and the final
scores."""
UI_POINTS = 320
"""Points the MLflow UI's charts fetch per curve (its `get-history-bulk-interval` calls' ``max_results``, MLflow
3.x): a chart of a whole run draws no more than these, whatever the store holds."""
PER_KEY = 100
"""Points kept of a per-update key: one per 1% of its updates, a chart's line with no step a reader can see at a
run's scale (the UI would draw `UI_POINTS`); what the import's minute allows: 320 a key were 365 k points and 86 s
of CPU for the 68 committed runs, 100 are ~125 k points (docs/tracking.md has the measured figure). A zoom into a
few updates shows fewer points than the run logged: the whole curve is the run's artifact metrics.csv."""


def kept_whole(key: str) -> bool:
    """Whether every point of ``key`` is stored (`WHOLE`)."""
    return key.startswith(WHOLE)


def evenly(steps: list[int], keep: int) -> list[int]:
    """``keep`` of the sorted ``steps`` (all of them when they are no more), evenly spaced by index, the first and the
    last included."""
    n = len(steps)
    if n <= keep:
        return steps
    if keep < 2:
        raise ValueError(f"keep: at least 2 points (the first and the last), got {keep}")
    return sorted({steps[round(i * (n - 1) / (keep - 1))] for i in range(keep)})


def thinned(points: Iterable[tuple[int, str, float]], keep: int = PER_KEY) -> list[tuple[int, str, float]]:
    """The (step, key, value) points an imported run stores (module docstring): one per key and step (the last given,
    as the store keeps it), every one of a `WHOLE` key or of a key with at most ``keep`` steps, ``keep`` evenly
    spaced steps of any other; sorted by key then step."""
    by_key: dict[str, dict[int, float]] = {}
    for step, key, value in points:
        by_key.setdefault(key, {})[step] = value
    out = []
    for key in sorted(by_key):
        values = by_key[key]
        steps = sorted(values)
        if not kept_whole(key):
            steps = evenly(steps, keep)
        out += [(step, key, values[step]) for step in steps]
    return out


def stored_count(path: str | os.PathLike, keep: int = PER_KEY) -> int:
    """How many points `thinned` keeps of a metrics.csv, counted from its lines' keys without reading their values
    (a progress bar's total, emml.runs.import_runs.import_runs): per key its lines, at most ``keep`` unless kept
    whole. 0 for an absent file."""
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        return 0
    counts = Counter(line.split(b",", 2)[1] for line in data.split(b"\n")[1:] if line.count(b",") == 2)
    return sum(n if n <= keep or kept_whole(key.decode(errors="replace")) else keep for key, n in counts.items())
