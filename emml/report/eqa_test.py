"""Issue 62's finding on the claims page, in one place: is EQA test reproduced under the paper's stated model?

Read from reproduce/experiments/eqa_answer.toml, whose first row is Table 2's Dual-Attention (Doom Easy, Aux; its runs
borrowed) and whose other rows each change one choice of the answer path the paper is silent on. The stated model's
EQA test is compared with the paper's Table 2 number by the claims' own threshold rule (emml/experiments/claims/
evidence.py: below it by more than Z standard errors is a contradiction), and each row with the blind prior (Text only,
emml/report/chance.py). The issue's rule: a row that clears the blind prior runs seeds 1 and 2 before anything
changes; while none does, EQA test is not reproduced at the profile's budget under the paper's stated model.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from emml.config.profiles import Profile
from emml.experiments.claims.evidence import HOLDS, REVERSED, Chance, Score, mean, seeds_text, threshold

EXPERIMENT = "experiments/eqa_answer"
"""The table of the answer path's arms; its first row is the paper's stated model."""
PAPER_TABLE, PAPER_ROW = "table2", "Dual-Attention"
"""Where the paper prints the number the stated model is held to (Table 2, Doom Easy, Aux, EQA test: 0.58)."""
DIFFICULTY, AUX, METRIC = "easy", True, "eqa_test"


@dataclass(frozen=True)
class Arm:
    """One row of the experiment: its label and its runs' EQA test (one Score per seed)."""

    label: str
    scores: list[Score]


def finding(arms: list[Arm], paper: float, chance: Chance, profile: str) -> list[str]:
    """The section's lines: the verdict in bold, then the numbers it rests on. ``arms[0]`` is the paper's stated
    model."""
    stated, others = arms[0], arms[1:]
    prior = chance.of(METRIC, DIFFICULTY)
    head = ["## EQA test under the paper's stated model (issue 62)", ""]
    if not stated.scores:
        return [*head, f"Waiting for Table 2's Dual-Attention, Doom Easy, Aux at the '{profile}' profile.", ""]
    check = threshold("EQA test, Easy · Aux", "Dual-Attention ≥ the paper's", stated.scores, paper)
    clear = [a.label for a in others if a.scores and mean(a.scores) > prior]  # a choice that might move it
    waiting = [a.label for a in others if not a.scores]
    if check.outcome == HOLDS:
        verdict = f"EQA test reproduced at the {profile} budget under the paper's stated model"
    elif check.outcome != REVERSED:
        verdict = f"EQA test within the error of the paper's at the {profile} budget: neither reproduced nor refuted"
    elif clear or waiting:  # below the paper, and an arm may still move it
        verdict = f"EQA test below the paper's at the {profile} budget under the paper's stated model; " + (
            ", ".join(f"'{a}'" for a in clear) + " clears the blind prior: its seeds 1 and 2 before anything changes"
            if clear
            else ", ".join(f"'{a}'" for a in waiting) + " still to run"
        )
    else:
        verdict = f"EQA test not reproduced at the {profile} budget under the paper's stated model"
    lines = [
        *head,
        f"**{verdict}.** Table 2's Dual-Attention, Doom Easy, Aux, against the paper's {paper:g}: {check.detail}. "
        f"The blind prior ({chance.source}) is {prior:.3f}: "
        + (f"{', '.join(clear)} above it." if clear else "no arm below is above it."),
        "",
        f"| {EXPERIMENT} row | EQA test | mean | EQA train (mean) | against the blind prior {prior:.3f} |",
        "|:--|:--|--:|--:|:--|",
    ]
    for a in arms:
        if not a.scores:
            lines.append(f"| {a.label} | no run yet | — | — | — |")
            continue
        m = mean(a.scores)
        trained = [s.train for s in a.scores if s.train is not None]
        train = f"{sum(trained) / len(trained):.3f}" if trained else "—"
        lines.append(
            f"| {a.label} | {seeds_text(a.scores)} | {m:.3f} | {train} | {'above' if m > prior else 'not above'} |"
        )
    lines += [
        "",
        f"{len(others)} of the answer path's silent choices changed one per row (`reproduce/{EXPERIMENT}.toml`). The "
        'train and test curves and the failures per question: docs/fidelity.md, "The answer path\'s silent choices".',
        "",
    ]
    return lines


def read_arms(profile: Profile, results_root: str | Path | None = None) -> list[Arm]:
    """The experiment's rows with their finished runs' EQA test under ``profile`` (each run a Score of its
    episodes, with its EQA train; no learning bar: the finding reads means, not whether a row learned)."""
    from emml.report.cells import build_cells, paper_numbers, table_results
    from emml.report.plan import plan_report

    plan = plan_report(EXPERIMENT, profile, results_root)
    results = table_results(plan.table, plan.profile, plan.results_root)
    rows = {r["run_name"]: r for r in results.to_dict("records")}
    arms = []
    for c in build_cells(plan, results, paper_numbers(plan.table.name)):
        if (c.difficulty, c.aux, c.metric) != (DIFFICULTY, AUX, METRIC):
            continue
        scores = [
            Score(name, int(r["seed"]), value, int(r["eval_episodes"]), int(r["frames"]), _train(r))
            for name, value in zip(c.runs, c.values)
            for r in [rows[name]]
        ]
        arms.append(Arm(c.row, scores))
    return arms


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
