"""A run of a claim's cell as the claims page reads it (emml/report/claims.py's `gather`): each way a claim's kind
may read its number (emml/experiments/claims/kinds.py, `Kind.read`): its results row, the frames at which its
evaluation curve first crosses a mark, or a diag/* figure at its last evaluation. The curve is read as every page
reads it (emml/runs/curve.py), so the claims page and the table pages about the same run read the same points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from emml.eval.metrics import TRAIN_COLUMNS
from emml.experiments.claims.evidence import Chance, Score
from emml.report.claims_settle import isnan
from emml.report.efficiency import run_efficiency
from emml.runs.curve import read_curve
from emml.runs.rundir import path_of


@dataclass
class Reading:
    """One run of a claim's cell, each way a kind may read its number (emml/experiments/claims/kinds.py, `RunReading`):
    its results row, or its curve read as every page reads it (`emml.runs.curve.read_curve`: its run dir's
    metrics.csv, else the MLflow run of its results row)."""

    run: Any
    """Its planned run (emml/report/plan.py): its spec and name."""
    row: dict
    """Its results row."""
    score: Score
    """Its number in the cell from its results row, with its seed, episodes, frames and learning bar."""
    columns: set
    """The table's results columns (another metric read from the row is a training column)."""
    run_root: str | Path
    chance: Chance

    @property
    def folder(self) -> Path:
        return path_of(self.run_root, self.run.spec.table, self.run.name)

    @property
    def run_id(self) -> str | None:
        return self.row.get("run_id")

    def result(self, metric: str) -> Score | None:
        if metric in self.columns:
            return self.score
        return None if isnan(self.row.get(metric)) else replace(self.score, value=float(self.row[metric]))

    def crossing(self, metric: str, mark: str) -> Score | None:
        """None also when the curve stops short of the run's frames by more than its gap (a crossing after it cannot
        be ruled out)."""
        spec, score = self.run.spec, self.score
        eff = run_efficiency(spec, self.run.name, self.run_root, self.chance, self.run_id)
        if not eff.found or metric not in eff.crossings:
            return None
        crossed = eff.crossings[metric][mark]
        if crossed is None and eff.last + eff.every < score.frames:
            return None
        value = math.inf if crossed is None else float(crossed)
        return Score(score.run, score.seed, value, 0, eff.last, every=eff.every)

    def last(self, key: str) -> Score | None:
        """Learned: either training split above its bar (a diag figure is about the conv both tasks read); a run with
        no training score has none (left out of 'learned'), never a placeholder margin."""
        points = read_curve(self.folder, [key], self.run_id).of(key)
        if not points:
            return None
        row, difficulty = self.row, self.run.spec.difficulty
        margins = [float(row[m]) - self.chance.bar(m, difficulty) for m in TRAIN_COLUMNS if not isnan(row.get(m))]
        train = max(margins) if margins else None
        return Score(self.score.run, self.score.seed, points[-1][1], 0, points[-1][0], train, 0.0, metric=key)
