"""What the claims page reads to weigh a reversal for being settled (issue 81 item 3; the rule:
emml/experiments/claims/settle.py): the nearest cell of the same row with two seeds or more, whose between-seed
variance a one-seed row borrows; each run's evaluation curve (read as every page reads it: emml/runs/curve.py); the
run that would give a one-seed row its next seed, with its campaign step; and the paper-literal run beside a No Aux
cell trained under the warm-up (issue 81 item 5).
"""

from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from emml.eval.metrics import BY_NAME, CURVE_METRICS
from emml.experiments.claims.evidence import Check, Score
from emml.experiments.claims.settle import MORE_FRAMES, settle
from emml.runs.curve import read_curve

WARM = re.compile(r"-warm(\d+)-")
"""A No Aux run under the warm-up (issue 61's rule: the answer kept off the image for its first N frames)."""


def spread_of(values: list[float]) -> float | None:
    """The between-seed sample variance of a cell's values; None with fewer than two seeds."""
    return float(np.var(values, ddof=1)) if len(values) >= 2 else None


def nearest(key: tuple, spreads: dict) -> tuple | None:
    """The nearest other cell of the same row and metric with a spread (two seeds or more): the same difficulty
    first, then the same aux, then any (ties by difficulty and aux, so the choice is the same every time). ``key``
    and the keys of ``spreads``: (row, difficulty, aux, metric); values (variance, seeds)."""
    row, d, a, m = key
    others = [k for k in spreads if k[0] == row and k[3] == m and k != key]
    if not others:
        return None
    return min(others, key=lambda k: (k[1] != d, k[2] != a, k[1], not k[2]))


def borrow(scores: dict, spreads: dict, label) -> dict:
    """``scores`` ((row, difficulty, aux, metric) → a cell's scores) with each one-seed cell's score given the
    between-seed variance of its `nearest` cell (`Score.borrowed`, named by ``label(difficulty, aux)``)."""
    out = {}
    for key, found in scores.items():
        source = nearest(key, spreads) if len(found) == 1 else None
        if source is None:
            out[key] = found
            continue
        variance, n = spreads[source]
        named = f"{source[0]}, {label(source[1], source[2])} ({n} seeds)"
        out[key] = [replace(found[0], borrowed=variance, borrowed_from=named)]
    return out


class Curves:
    """Each run's evaluation curves as every page reads them (`emml.runs.curve.read_curve`: its metrics.csv, else its
    MLflow run): run name → its run dir (``folders``) and the MLflow run id of its results row (``run_ids``)."""

    def __init__(self, folders: dict[str, Path], run_ids: dict[str, str] | None = None):
        self.folders = folders
        self.run_ids = run_ids or {}

    def __call__(self, score: Score) -> dict[int, float] | None:
        """The run's curve of the score's metric (frames → value): a greedy evaluation metric's key (eval/sgn_test
        for sgn_test), or the score's diag/* key itself; None when the run has no curve here or none of that key (a
        transfer score)."""
        folder = self.folders.get(score.run)
        if folder is None:
            return None
        key = BY_NAME[score.metric].key if score.metric in CURVE_METRICS else score.metric
        points = read_curve(folder, [key], self.run_ids.get(score.run)).of(key)
        return dict(points) if points else None


def next_seed(plan, row: str, difficulty: str, aux: bool, metric: str, found: list[str]) -> str:
    """The run that gives the cell its next seed, 'table/name': the first declared run of the cell with no results
    row, else the cell's run at the seed after its highest (declared nowhere yet)."""
    declared = plan.cell_runs(row, difficulty, aux, metric)
    absent = [r for r in declared if r.name not in found]
    if absent:
        return f"{absent[0].spec.table}/{absent[0].name}"
    if not declared:
        return f"a second seed of {row}"
    spec = max((r.spec for r in declared), key=lambda s: s.seed)
    more = replace(spec, seed=spec.seed + 1)
    return f"{more.table}/{more.run_name(plan.profile)}"


def settle_all(checks: list[Check], curves: Curves, seconds: dict[str, str]) -> list[Check]:
    """Each reversed, learned check weighed for being settled (`settle`); ``seconds``: run name → the run that gives
    its cell its next seed."""

    def second(scores: list[Score]) -> str:
        return seconds.get(scores[0].run, f"a second seed of {scores[0].run}")

    return [settle(c, curves, second) for c in checks]


def literal_of(name: str) -> str | None:
    """The paper-literal twin of a warm-up run's name (no warm-up: '-warm400000' dropped); None for another run."""
    return WARM.sub("-", name) if WARM.search(name) else None


def warm_frames(names: list[str]) -> int | None:
    """The warm-up every one of ``names`` trained under (frames), None when not all of them did."""
    found = {int(m.group(1)) for m in (WARM.search(n) for n in names) if m}
    return found.pop() if names and len(found) == 1 and all(WARM.search(n) for n in names) else None


def literal_rows(profile, results_root) -> dict[str, dict]:
    """Run name → results row, over every results CSV of the profile (the tables' and the experiments': a literal
    run may be an experiment's arm, results/noaux_*)."""
    from emml.report.cells import results_path
    from emml.runs.results import read_results

    folder = results_path("table2", profile, results_root).parent.parent
    out: dict[str, dict] = {}
    for csv in sorted(folder.glob(f"*/{profile.name}.csv")):
        df = read_results(csv)
        if not df.empty and "run_name" in df:
            out.update({r["run_name"]: r for r in df.to_dict("records")})
    return out


def spreads(claim, cells, rows: dict, columns: set, involved: set) -> dict:
    """(row, difficulty, aux, metric) → (between-seed variance, seeds) of every cell of the claim's rows and metrics
    in the whole table (not only the claim's columns) with two seeds or more."""
    out = {}
    for m in claim.metrics:
        cell_metric = m if m in columns else m.replace("_train", "_test")
        for c in (c for c in cells if c.metric == cell_metric and c.row in involved):
            values = c.values if m in columns else [float(rows[n][m]) for n in c.runs if not isnan(rows[n].get(m))]
            variance = spread_of(values)
            if variance is not None:
                out[(c.row, c.difficulty, c.aux, m)] = (variance, len(values))
    return out


def literal(evidence: list[dict], plan) -> list[dict]:
    """Beside each cell whose runs all trained under the No Aux warm-up, the paper-literal run of the same row
    (no warm-up) where a results CSV of the profile has one (issue 81 item 5)."""
    if not any(warm_frames(e["runs"]) for e in evidence):
        return []
    rows = literal_rows(plan.profile, plan.results_root)
    out = []
    for e in evidence:
        if not warm_frames(e["runs"]):
            continue
        metric = e["column"]
        for name in dict.fromkeys(literal_of(n) for n in e["runs"]):
            row = rows.get(name)
            if row is None or isnan(row.get(metric)):
                continue
            entry = {**{k: e[k] for k in ("row", "setting", "metric")}, "run": f"{row['table']}/{name}"}
            out.append({**entry, "value": float(row[metric])})
    return out


def isnan(v) -> bool:
    """Whether a results row's value cannot be read as a number (absent, empty, NaN)."""
    try:
        return math.isnan(float(v))
    except (TypeError, ValueError):
        return True


def settle_costs(checks: list[Check], costs: dict) -> list[str]:
    """Each run that would settle a provisional reversal of ``checks``, once, with its campaign step and cost
    (``costs``: emml/report/claims.py's campaign_costs; 'in no step of the campaign' where none trains it)."""
    wanted = []
    for c in checks:
        if c.unsettled:
            wanted += [(r, c.what) for r in c.settle_by]
    out = []
    for run, what in dict.fromkeys(wanted):
        if run == MORE_FRAMES:
            out.append(f"more frames for the runs of {what} (no campaign step trains them further)")
            continue
        table, _, name = run.partition("/")
        out.append(f"`{run}` ({what}): {costs.get((table, name), 'in no step of the campaign')}")
    return list(dict.fromkeys(out))
