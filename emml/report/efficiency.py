"""Sample efficiency (issue 49): per run, the frames at which its greedy accuracy first leaves chance and first
reaches 0.5 and 0.9, on SGN and EQA, train and test split, read from the periodic evaluation points of the run's
metrics mirror (`runs/<table>/<run>/metrics.csv`, keys `eval/sgn_test`, `eval/eqa_train`, ...: the trainer evaluates
greedily every `eval_every` frames on `eval_episodes` episodes per task and split), as every page reads a run's curve
(emml/runs/curve.py: its metrics.csv, else its MLflow run).

The table pages show them run by run (`markdown`); the claims page decides the paper's speed claims with them ("reward
shaping and the task indicator help with learning speed", §5.3, Figure 9: `emml/report/claims.py`, kind `faster`).
A crossing is only as fine as the evaluation cadence: a run evaluated every 100,000 frames that first leaves chance
at 300,000 left it somewhere after 200,000.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from emml.eval.metrics import BY_NAME, CURVE_METRICS, label
from emml.experiments.claims.claim_format import MARKS  # the crossings: leaving chance (above chance + LEAVE), 0.5, 0.9
from emml.experiments.claims.evidence import LEAVE, Chance, frames_text
from emml.report.cells import table_results
from emml.runs.curve import RunCurve, read_curve

__all__ = ["LEAVE", "frames_text", "first_crossing", "run_efficiency", "table_efficiency", "markdown"]
UNIFORM_CHANCE = Chance()
"""The uniform floor (SGN 0.2, EQA 1/3; emml/experiments/claims/evidence.py): a crossing asked for without a
difficulty (`first_crossing`); a run's and a table's crossings read the task's blind ceiling (`task_ceiling`)."""


def level(metric: str, mark: str, floor: float) -> float:
    """The accuracy a crossing `mark` asks for: above `floor` (chance) + LEAVE for 'chance', else the number."""
    return floor + LEAVE if mark == "chance" else float(mark)


def first_crossing(points: list[tuple[int, float]], metric: str, mark: str, floor: float | None = None) -> int | None:
    """The first frame count at which the curve crosses `mark` (`level`; `floor`: chance, by default the uniform
    chance of the metric's task); None when it never does."""
    bar = level(metric, mark, UNIFORM_CHANCE.of(metric, "easy") if floor is None else floor)
    for step, value in points:
        if (value > bar) if mark == "chance" else (value >= bar):
            return step
    return None


@dataclass
class RunEfficiency:
    """One run's crossings."""

    run: str
    row: str
    difficulty: str
    aux: bool
    seed: int
    crossings: dict[str, dict[str, int | None]] = field(default_factory=dict)
    """metric → mark → the first frame count at the crossing (None: not by `last`); a metric the run never
    evaluated (a single-task run's other task) is absent."""
    last: int = 0
    """The frames of the last evaluation point."""
    every: int = 0
    """The largest gap between evaluation points in frames (0 with one point): a crossing is known to that
    resolution (the gaps of a run may alternate, e.g. 99,328 / 100,352)."""
    found: bool = True
    """False when the run has no metrics mirror here (its run dir is on the machine that trained it)."""
    damaged: bool = False
    """True when its metrics mirror is here but damaged (a line that is not a point: named once in a note)."""


CURVE_KEYS = {BY_NAME[m].key: m for m in CURVE_METRICS}
"""A curve metric's key in a run's curve (eval/sgn_test) → the metric (sgn_test)."""


def curves(curve: RunCurve) -> dict[str, list[tuple[int, float]]]:
    """metric → its greedy evaluation points (frames, accuracy) in frame order, from a run's curve as every page reads
    it (`emml.runs.curve.read_curve`); a metric with no point is absent."""
    return {m: curve.of(k) for k, m in CURVE_KEYS.items() if curve.of(k)}


def run_efficiency(
    spec, name: str, run_root: str | Path, chance: Chance | None = None, run_id: str | None = None
) -> RunEfficiency:
    """The crossings of one declared run (a RunSpec, its run name ``name`` as planned) from its curve (its run dir
    under `run_root`, else MLflow run ``run_id``: `emml.runs.curve.read_curve`); 'leaves chance' above `chance`
    (default the task's blind ceiling, emml/report/chance.py) + LEAVE."""
    from emml.report.chance import task_ceiling
    from emml.runs.rundir import path_of

    chance = chance if chance is not None else task_ceiling()
    eff = RunEfficiency(name, spec.row, spec.difficulty, spec.aux, spec.seed)
    curve = read_curve(path_of(run_root, spec.table, name), CURVE_KEYS, run_id)
    found = curves(curve)
    if not found:
        eff.found, eff.damaged = False, curve.damaged
        return eff
    steps = sorted({s for points in found.values() for s, _ in points})
    eff.last = steps[-1]
    eff.every = max((b - a for a, b in zip(steps, steps[1:])), default=0)
    for metric in CURVE_METRICS:
        if metric in found:
            floor = chance.of(metric, spec.difficulty)
            eff.crossings[metric] = {mark: first_crossing(found[metric], metric, mark, floor) for mark in MARKS}
    return eff


def table_efficiency(
    plan, names: list[str], chance: Chance | None = None, run_ids: dict[str, str] | None = None
) -> list[RunEfficiency]:
    """The crossings of the named runs of the plan's table (the runs its page shows), in the table's run order, from
    their curves (run dirs under the plan's run_root, else their MLflow runs: ``run_ids``, run name → run id, by
    default their results rows'); chance: the task's blind ceiling (emml/report/chance.py) unless given."""
    from emml.report.chance import task_ceiling

    chance = chance if chance is not None else task_ceiling()
    run_ids = run_ids if run_ids is not None else results_run_ids(plan)
    wanted = set(names)
    return [
        run_efficiency(r.spec, r.name, plan.run_root, chance, run_ids.get(r.name))
        for r in plan.runs
        if r.name in wanted
    ]


def results_run_ids(plan) -> dict[str, str]:
    """Run name → the MLflow run id its results row records, over the plan's table and the tables it borrows from."""
    results = table_results(plan.table, plan.profile, plan.results_root)
    return {} if results.empty else dict(zip(results["run_name"], results["run_id"]))


def markdown(runs: list[RunEfficiency], metrics: tuple[str, ...] = CURVE_METRICS, chance: Chance | None = None) -> str:
    """The page's sample-efficiency section: one line per run, per metric its three crossings."""
    from emml.config.env_kinds import env_label

    runs = [r for r in runs]
    if not runs:
        return ""
    shown = [m for m in metrics if any(m in r.crossings for r in runs)]
    from emml.report.chance import chance_text, task_ceiling

    chance = chance if chance is not None else task_ceiling()
    every = sorted({r.every for r in runs if r.every})
    cadence = ", ".join(f"{e:,}" for e in every) or "—"
    difficulties = tuple(dict.fromkeys(r.difficulty for r in runs))
    lines = [
        "### Sample efficiency",
        "",
        "Frames at which each run's greedy accuracy (its periodic evaluation in `metrics.csv`) first leaves chance "
        f"(above chance + {LEAVE:.2f}; chance is the best a model that sees no frame can score, {chance.source}: "
        f"{chance_text(chance, difficulties)}), then reaches 0.5 and 0.9, as 'leaves chance / 0.5 / 0.9'; >F: not by "
        f"its last evaluation at F frames. Evaluations at most {cadence} frames apart: a crossing is known to that "
        "resolution.",
        "",
    ]
    header = ["Run", "Setting", "seed"] + [label(m) for m in shown]
    lines += ["| " + " | ".join(header) + " |", "|:--|:--|--:|" + ":--|" * len(shown)]
    for r in runs:
        setting = f"{env_label(r.difficulty)} · {'Aux' if r.aux else 'No Aux'}"
        cells = []
        for m in shown:
            if not r.found:
                cells.append("metrics.csv damaged" if r.damaged else "no metrics.csv here")
            elif m not in r.crossings:
                cells.append("—")
            else:
                cells.append(" / ".join(frames_text(r.crossings[m][k], r.last) for k in MARKS))
        lines.append(f"| {r.row} | {setting} | {r.seed} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
