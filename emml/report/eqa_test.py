"""The claims page's EQA box (issues 62, 81, 82): is EQA test reproduced under the paper's stated model, on which
seeds, and does the question gate explain it?

The stated model is Table 2's Dual-Attention, Doom Easy, Aux (the first row of each answer-path experiment borrows
its runs). Its EQA test is compared with the paper's Table 2 number by the claims' own threshold rule (emml/
experiments/claims/evidence.py: below it by more than Z standard errors is a contradiction). The box lists every seed
of it with its EQA test and its question gate at the run's last checkpoint (the ``diag/gate_*`` figures of
emml/eval/diagnose_gate.py, read from the run dir's metrics.csv: the gate's mass on the answer's attribute on the
test questions whose subject no training question names, per attribute, and the answer channels it shuts), then
every other row of the answer-path experiments (`EXPERIMENTS`: each changes one choice of the answer path the paper
is silent on) with its EQA test per seed. Each row is read against chance as the caller passes it (`Chance.of`: the
task's blind ceiling, emml/report/chance.py). The issue 62 rule: a row above chance on fewer than 3 seeds runs its
seeds 1 and 2 before anything changes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from emml.config.profiles import Profile
from emml.experiments.claims.evidence import HOLDS, REVERSED, Chance, Score, mean, threshold

EXPERIMENTS = ("experiments/eqa_answer", "experiments/eqa_gate", "experiments/eqa_readout")
"""The answer path's experiments; the first row of each is the paper's stated model (Table 2's runs, borrowed)."""
EXPERIMENT = EXPERIMENTS[0]
"""The experiment whose first row gives the stated model's runs."""
PAPER_TABLE, PAPER_ROW = "table2", "Dual-Attention"
"""Where the paper prints the number the stated model is held to (Table 2, Doom Easy, Aux, EQA test: 0.58)."""
DIFFICULTY, AUX, METRIC = "easy", True, "eqa_test"
SETTLED_SEEDS = 3
"""A row above chance on fewer seeds than this runs its seeds 1 and 2 before anything changes (issue 62)."""
GATE_KEYS = ("diag/gate_on_attribute", "diag/gate_on_color", "diag/gate_on_object", "diag/gate_dead")
"""The question gate's figures a run dir's metrics.csv holds (emml/eval/diagnose_gate.py `SCALARS`)."""


@dataclass(frozen=True)
class Gate:
    """One run's question gate at its last point in metrics.csv (emml/eval/diagnose_gate.py)."""

    on_attribute: float
    """Mass on the answer's attribute over the gate's total, mean over the unseen-subject test questions."""
    on_color: float | None
    """The same over the colour questions only; None where none is asked."""
    on_object: float | None
    """The same over the object questions only; None where none is asked."""
    dead: int
    """Answer words whose gate channel is 0 on every question."""
    history: dict[str, tuple[tuple[int, float], ...]] = field(default_factory=dict, compare=False)
    """Each of `GATE_KEYS` over the frames trained, (step, value) as the run logged it: every evaluation of a run
    trained with the diagnostic, one point at its final checkpoint for a run filled afterwards (`emml diagnose
    --gate --record`). What the gate figure draws (emml/report/gate_figure.py)."""

    def text(self) -> str:
        """'0.69 (colour 0.18 · object 1.00)'."""
        parts = [f"{k} {v:.2f}" for k, v in (("colour", self.on_color), ("object", self.on_object)) if v is not None]
        return f"{self.on_attribute:.2f}" + (f" ({' · '.join(parts)})" if parts else "")


@dataclass(frozen=True)
class Arm:
    """One row of an experiment: its label and its runs' EQA test (one Score per seed), with each run's gate."""

    label: str
    scores: list[Score]
    gates: dict[str, Gate] = field(default_factory=dict)
    """Run name → its gate figures; a run without them (trained before issue 82, not yet filled) is absent."""
    experiment: str = EXPERIMENT
    """The experiment the row is declared in."""


def _gate_cells(arm: Arm, score: Score) -> tuple[str, str]:
    """The run's gate text and its count of shut answer channels; '—' for a run without its figures."""
    gate = arm.gates.get(score.run)
    return ("—", "—") if gate is None else (gate.text(), str(gate.dead))


def _per_seed(scores: list[Score]) -> str:
    return " · ".join(f"{s.value:.3f} (s{s.seed})" for s in scores)


def _colour_per_seed(arm: Arm) -> str:
    found = [(s.seed, arm.gates[s.run].on_color) for s in arm.scores if s.run in arm.gates]
    return " · ".join(f"{v:.2f} (s{seed})" for seed, v in found if v is not None) or "—"


def finding(arms: list[Arm], paper: float, chance: Chance, profile: str, figure: str | None = None) -> list[str]:
    """The box's lines: the verdict in bold, the stated model's seeds with their gates (and ``figure``, the gate
    figure's file beside the page, when one was drawn: emml/report/gate_figure.py), then the answer path's other
    rows. ``arms[0]`` is the paper's stated model."""
    stated, others = arms[0], arms[1:]
    prior = chance.of(METRIC, DIFFICULTY)
    head = ["## EQA test under the paper's stated model (issues 62, 81, 82)", ""]
    if not stated.scores:
        return [*head, f"Waiting for Table 2's Dual-Attention, Doom Easy, Aux at the '{profile}' profile.", ""]
    check = threshold("EQA test, Easy · Aux", "Dual-Attention ≥ the paper's", stated.scores, paper)
    clear = [a for a in others if a.scores and mean(a.scores) > prior]
    unsettled = [a for a in clear if len(a.scores) < SETTLED_SEEDS]  # above chance: its seeds first
    settled = [a for a in clear if len(a.scores) >= SETTLED_SEEDS]
    waiting = [a for a in others if not a.scores]
    if check.outcome == HOLDS:
        verdict = f"EQA test reproduced at the {profile} budget under the paper's stated model"
    elif check.outcome != REVERSED:
        verdict = f"EQA test within the error of the paper's at the {profile} budget: neither reproduced nor refuted"
    elif unsettled or waiting:  # below the paper, and an arm may still move it
        verdict = f"EQA test below the paper's at the {profile} budget under the paper's stated model; " + (
            ", ".join(f"'{a.label}'" for a in unsettled) + " clears chance: its seeds 1 and 2 before anything changes"
            if unsettled
            else ", ".join(f"'{a.label}'" for a in waiting) + " still to run"
        )
    else:
        verdict = f"EQA test not reproduced at the {profile} budget under the paper's stated model" + (
            "; reached by a choice the paper does not state: "
            + ", ".join(f"'{a.label}' (mean {mean(a.scores):.3f} on {len(a.scores)} seeds)" for a in settled)
            if settled
            else ""
        )
    above = [s for s in stated.scores if s.value > prior]
    lines = [
        *head,
        f"**{verdict}.** Table 2's Dual-Attention, Doom Easy, Aux, against the paper's {paper:g}: {check.detail}. "
        f"Chance is {prior:.3f} ({chance.source}): "
        + (
            f"{len(above)} of its {len(stated.scores)} seeds above it ({_per_seed(above)})."
            if above
            else f"none of its {len(stated.scores)} seeds above it."
        ),
        "",
        "The stated model per seed, with its question gate at the run's last checkpoint (`emml diagnose --gate`): on "
        "the EQA test questions whose subject no training question names ('torch', 'blue'), the mass of x_sent "
        "(Eq. 4) on the answer's attribute channels over its total, overall and per attribute; and the answer words "
        "whose gate channel is 0 on every question (a ReLU unit no gradient reaches).",
        "",
        f"| seed | EQA test | EQA train | against chance {prior:.3f} | gate on the answer's attribute | "
        "answer channels shut |",
        "|--:|--:|--:|:--|:--|--:|",
    ]
    for s in stated.scores:
        train = "—" if s.train is None else f"{s.train:.3f}"
        gate, dead = _gate_cells(stated, s)
        lines.append(
            f"| {s.seed} | {s.value:.3f} | {train} | {'above' if s.value > prior else 'not above'} | {gate} | {dead} |"
        )
    if figure is not None:
        lines += [
            "",
            f"![The stated model's question gate over training, per seed]({figure})",
            "",
            "The gate over training (colour questions, object questions), a line per seed: every evaluation of a "
            "run trained with the diagnostic, one point at the final checkpoint of a run filled afterwards.",
        ]
    lines += [
        "",
        "The answer path's other rows, each changing one choice the paper is silent on "
        f"(`reproduce/{'`, `reproduce/'.join(f'{e}.toml' for e in EXPERIMENTS)}`):",
        "",
        f"| experiment · row | EQA test per seed | mean | gate on a colour question per seed | against chance "
        f"{prior:.3f} |",
        "|:--|:--|--:|:--|:--|",
    ]
    for a in others:
        name = f"{a.experiment.removeprefix('experiments/')} · {a.label}"
        if not a.scores:
            lines.append(f"| {name} | no run yet | — | — | — |")
            continue
        m, against = mean(a.scores), "above" if mean(a.scores) > prior else "not above"
        lines.append(f"| {name} | {_per_seed(a.scores)} | {m:.3f} | {_colour_per_seed(a)} | {against} |")
    lines += [
        "",
        "The train and test curves and the failures per question: docs/fidelity.md, \"The answer path's silent "
        'choices"; the gate on "what colour is the torch" per seed: docs/fidelity.md, "\'blue\', read from the gates".',
        "",
    ]
    return lines


def read_gate(metrics_csv: Path) -> Gate | None:
    """A run's gate figures at the last step its metrics mirror holds them (`GATE_KEYS`); None without them (or with
    a damaged mirror, said once by `points_or_none`)."""
    from emml.runs.records import points_or_none

    points = points_or_none(metrics_csv) or []
    by_step: dict[str, dict[int, float]] = {}
    for step, key, value in points:
        if key in GATE_KEYS:
            by_step.setdefault(key, {})[step] = value  # a point logged twice (a resumed step) keeps its last value
    if "diag/gate_on_attribute" not in by_step or "diag/gate_dead" not in by_step:
        return None
    history = {k: tuple(sorted(v.items())) for k, v in by_step.items()}
    value = {k: h[-1][1] for k, h in history.items()}  # at the last step each figure was logged
    return Gate(
        value["diag/gate_on_attribute"],
        value.get("diag/gate_on_color"),
        value.get("diag/gate_on_object"),
        int(value["diag/gate_dead"]),
        history,
    )


def read_experiment(
    experiment: str, profile: Profile, results_root: str | Path | None = None, run_root: str | Path | None = None
) -> list[Arm]:
    """One experiment's rows with their finished runs' EQA test under ``profile`` (each run a Score of its
    episodes, with its EQA train; no learning bar: the box reads means, not whether a row learned) and each run's
    gate from its run dir (`read_gate`; its table's dir for a borrowed row)."""
    from emml.report.cells import build_cells, paper_numbers, table_results
    from emml.report.plan import plan_report
    from emml.runs.rundir import METRICS, path_of

    plan = plan_report(experiment, profile, results_root, run_root)
    results = table_results(plan.table, plan.profile, plan.results_root)
    rows = {r["run_name"]: r for r in results.to_dict("records")}
    planned = plan.by_name()
    arms = []
    for c in build_cells(plan, results, paper_numbers(plan.table.name)):
        if (c.difficulty, c.aux, c.metric) != (DIFFICULTY, AUX, METRIC):
            continue
        scores = [
            Score(name, int(r["seed"]), value, int(r["eval_episodes"]), int(r["frames"]), _train(r))
            for name, value in zip(c.runs, c.values)
            for r in [rows[name]]
        ]
        gates = {}
        for s in scores:
            gate = read_gate(path_of(plan.run_root, planned[s.run].spec.table, s.run) / METRICS)
            if gate is not None:
                gates[s.run] = gate
        arms.append(Arm(c.row, scores, gates, experiment))
    return arms


def read_arms(
    profile: Profile, results_root: str | Path | None = None, run_root: str | Path | None = None
) -> list[Arm]:
    """The stated model (the first row of `EXPERIMENT`), then every other row of each of `EXPERIMENTS` in order."""
    first, *rest = EXPERIMENTS
    stated, *arms = read_experiment(first, profile, results_root, run_root)
    for experiment in rest:
        arms += read_experiment(experiment, profile, results_root, run_root)[1:]  # its first row: the stated model
    return [stated, *arms]


def _train(row: dict) -> float | None:
    import pandas as pd

    value = row.get("eqa_train")
    return None if pd.isna(value) else float(value)  # absent or NaN: a row without its training score


def paper_value() -> float:
    """The paper's Table 2 number for Dual-Attention, Doom Easy, Aux, EQA test."""
    from emml.report.cells import paper_numbers

    paper = paper_numbers(PAPER_TABLE)
    (value,) = paper[
        (paper["row"] == PAPER_ROW)
        & (paper["difficulty"] == DIFFICULTY)
        & (paper["aux"] == AUX)
        & (paper["metric"] == METRIC)
    ]["value"]
    return float(value)
