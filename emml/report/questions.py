"""EQA test per question beside its blind ceiling, and one grounded summary a prior cannot pass (issue 81, item 2).

As one number, EQA test cannot tell grounding from answer priors: on Doom Easy's 8 test questions the best fixed answer
per question already scores 0.5625 (emml/envs/ceiling.py, enumerated from the episode generator), above the paper's
own Dual-Attention EQA test in two of its four columns. So each question's score is shown beside its ceiling (the
probability of its best fixed answer), read from results/<table>/<profile>-questions.csv (the final evaluation's
successes per question: emml/eval/evaluate.py `Scores.questions`, `emml rescore --questions` for older runs), and
summarised by

    grounded EQA  G = mean over questions q with c_q < 1 of (s_q − c_q) / (1 − c_q)

(s_q: the run's accuracy on q, c_q: q's ceiling): 0 for a blind policy that gives every question its best answer, 1 for
a perfect score, below 0 for a policy worse than that prior on average; no policy that reads no frame exceeds 0 in
expectation, since c_q is the most any fixed answer scores on q. A question whose ceiling is 1.0 (one answer is
always right: 'which short object is blue in color' → torch) says nothing about grounding and is left out (the page
names it). Its standard error is binomial: sqrt(Σ s_q(1 − s_q) / n_q / (1 − c_q)²) / Q.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from emml.eval.metrics import label as metric_label
from emml.report.cells import Cell, level_label
from emml.runs.results import questions_path, read_questions

METRIC = "eqa_test"
"""The table metric whose runs are read per question."""
EQA_TEST = metric_label(METRIC)
"""The column head of the per-question matrix's accuracy, as every table spells it."""


@dataclass(frozen=True)
class Grounded:
    """The grounded summary of one run on one split (`grounded`)."""

    value: float
    """G: the mean over the counted questions of (score − ceiling) / (1 − ceiling); nan when none is counted."""
    se: float
    """Its binomial standard error: sqrt(Σ s(1 − s)/n / (1 − c)²) / Q."""
    counted: tuple[str, ...]
    """The questions G averages over (ceiling < 1)."""
    left_out: tuple[str, ...]
    """The questions left out: ceiling 1.0 (a fixed answer is always right)."""


def grounded(per_question: pd.DataFrame) -> Grounded:
    """G of one run on one split from its rows (index: question; columns successes, episodes, ceiling)."""
    missing = {"successes", "episodes", "ceiling"} - set(per_question.columns)
    if missing:
        raise ValueError(f"per-question rows need columns successes, episodes and ceiling; missing {sorted(missing)}")
    bad = per_question[~per_question["ceiling"].between(0, 1) | (per_question["episodes"] <= 0)]
    if not bad.empty:
        raise ValueError(f"question {bad.index[0]!r}: ceiling must lie in [0, 1] and episodes be > 0")
    full = per_question["ceiling"] >= 1
    rows = per_question[~full]
    s = rows["successes"] / rows["episodes"]
    margin = 1 - rows["ceiling"]
    lifts = (s - rows["ceiling"]) / margin  # (s_q − c_q) / (1 − c_q)
    var = (s * (1 - s) / rows["episodes"]) / margin**2
    q = len(rows)
    value = float(lifts.mean()) if q else float("nan")
    se = float(np.sqrt(var.sum()) / q) if q else float("nan")
    return Grounded(value, se, tuple(rows.index), tuple(per_question.index[full]))


def ceilings_of(difficulty: str, split: str) -> pd.DataFrame:
    """The split's EQA questions (index, the generator's order) with their best fixed answer ('best') and its
    probability ('ceiling'), enumerated (emml/envs/ceiling.py)."""
    from emml.envs.ceiling import ceiling_table

    table = ceiling_table(difficulty, "eqa", split)
    return table.set_index("text")[["best", "probability"]].rename(columns={"probability": "ceiling"})


def run_rows(counts: pd.DataFrame, run: str, split: str, ceilings: pd.DataFrame) -> pd.DataFrame:
    """One run's rows of a split (index: question, in ``ceilings``' order) with their ceiling; a question the
    generator does not ask in that split is a ValueError naming it."""
    mine = counts[(counts["run_name"] == run) & (counts["task"] == "eqa") & (counts["split"] == split)]
    unknown = sorted(set(mine["question"]) - set(ceilings.index))
    if unknown:
        raise ValueError(f"{run}: {unknown} are not EQA {split} questions; allowed: {list(ceilings.index)}")
    mine = mine.set_index("question")[["successes", "episodes"]]
    return mine.join(ceilings["ceiling"], how="inner").reindex([q for q in ceilings.index if q in mine.index])


def section(results_csv: str | Path, cells: list[Cell], results: pd.DataFrame) -> list[str]:
    """The table page's section (markdown lines): per difficulty, the questions with their best fixed answer and
    ceiling, then each run behind an EQA test cell: its EQA test per question, G on test and on train. The counts
    are read from the per-question file beside ``results_csv`` and beside the results tables of the runs' own
    tables (a borrowed run's: Table 3's DA Multi-Task is Table 2's), only the rows of the results row's training
    (run_id); runs without them are named. [] when the table has no EQA test cell with runs."""
    from emml.envs.ceiling import split_ceiling

    eqa = [c for c in cells if c.metric == METRIC and c.runs]
    if not eqa or results.empty:
        return []
    results_csv = Path(results_csv)
    paths = [questions_path(results_csv)]  # the table's own, then those of the tables it borrows runs from
    paths += [questions_path(results_csv.parent.parent / t / results_csv.name) for t in results["table"].unique()]
    paths = list(dict.fromkeys(paths))
    counts = pd.concat([read_questions(p) for p in paths], ignore_index=True)
    ids = results.set_index("run_name")["run_id"].astype(str)
    counts = counts[counts["run_id"] == counts["run_name"].map(ids)]  # an earlier training's rows are not read
    seeds = results.set_index("run_name")["seed"]
    lines = [
        "## EQA test per question, beside the blind ceiling",
        "",
        f"Each question's EQA test accuracy in the final evaluation ({', '.join(f'`{_shown(p)}`' for p in paths)}) "
        "beside its **ceiling**: the "
        "probability of the best fixed answer to it, enumerated from the episode generator (emml/envs/ceiling.py), "
        "what a model that sees no frame can score at most. "
        "**Grounded EQA** G = mean over questions of (score − ceiling) / (1 − ceiling): 0 for the best "
        "blind answer to every question, 1 for a perfect score, below 0 under that prior; ± its binomial standard "
        "error. G train is the same over the training questions.",
        "",
    ]
    missing = []
    for difficulty in dict.fromkeys(c.difficulty for c in eqa):
        test, train = ceilings_of(difficulty, "test"), ceilings_of(difficulty, "train")
        labels = {q: f"Q{i}" for i, q in enumerate(test.index, 1)}
        matrix, left_out = [], set()
        for cell in (c for c in eqa if c.difficulty == difficulty):
            for run in cell.runs:
                rows = run_rows(counts, run, "test", test)
                if rows.empty:
                    missing.append(run)
                    continue
                g, g_train = grounded(rows), grounded(run_rows(counts, run, "train", train))
                left_out.update(g.left_out)
                line = {"row": f"{cell.row} · {level_label('aux', cell.aux)}", "seed": int(seeds[run])}
                line[EQA_TEST] = f"{rows['successes'].sum() / rows['episodes'].sum():.3f}"
                for q, label in labels.items():
                    line[label] = f"{rows.at[q, 'successes'] / rows.at[q, 'episodes']:.2f}" if q in rows.index else "–"
                line["G test ± SE"] = _g(g, with_se=True)
                line["G train"] = _g(g_train)
                matrix.append(line)
        if not matrix:
            continue
        legend = pd.DataFrame(
            {
                "": list(labels.values()),
                "question": list(test.index),
                "best fixed answer": list(test["best"]),
                "ceiling": [f"{c:.3f}" for c in test["ceiling"]],
            }
        )
        out = pd.DataFrame(matrix)
        prior = {
            "row": "ceiling (best fixed answer)",
            "seed": "",
            EQA_TEST: f"{split_ceiling(difficulty, 'eqa', 'test'):.3f}",
        }
        prior |= {label: f"{test.at[q, 'ceiling']:.2f}" for q, label in labels.items()}
        out.loc[len(out)] = prior | {"G test ± SE": "0", "G train": "0"}
        lines += [
            f"### {level_label('difficulty', difficulty)}",
            "",
            legend.to_markdown(index=False, disable_numparse=True),
            "",
        ]
        lines += [out.fillna("").to_markdown(index=False, disable_numparse=True), ""]
        if left_out:
            shown = ", ".join(f"{labels[q]} ({q!r})" for q in test.index if q in left_out)
            lines += [f"Left out of G: {shown}: ceiling 1.0, a fixed answer is always right.", ""]
    if missing:
        lines += [f"Not yet counted per question (`emml rescore --questions`): {', '.join(missing)}.", ""]
    return lines


def _g(g: Grounded, with_se: bool = False) -> str:
    if np.isnan(g.value):
        return "–"
    value = round(g.value, 2) + 0.0  # no '-0.00' for a value that rounds to zero
    return f"{value:+.2f} ± {g.se:.2f}" if with_se else f"{value:+.2f}"


def _shown(path: Path) -> str:
    from emml.config.paths import project_root

    path = Path(path)
    return str(path.relative_to(project_root())) if path.is_relative_to(project_root()) else str(path)
