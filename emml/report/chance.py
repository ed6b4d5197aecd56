"""Chance as a blind model scores it here (issue 60): the Text only row, which sees no frame, per difficulty, task
and split, read from a profile's results (Table 2 for Doom, Table 5 for the House) or from the paper's own tables.
The claims page, the sample-efficiency tables and the curves' chance lines all read it (emml/experiments/claims/
evidence.py: `Chance`, never below the uniform chance)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from emml.config.profiles import Profile
from emml.experiments.claims.evidence import Chance
from emml.experiments.metrics import CHANCE_COLUMNS, label

BLIND_MODEL = "text_only"
"""The model that sees no frame: its score is the answer and target prior a blind agent can learn here."""
BLIND_TABLES = ("table2", "table5")
"""The tables that hold a blind row (Doom Easy and Hard; the House)."""
COLUMNS = CHANCE_COLUMNS
"""The columns a blind prior is measured on: each metric's declared `chance` (emml/experiments/metrics.py)."""


def blind_prior(profile: Profile, results_root: str | Path | None = None) -> Chance:
    """The profile's Text only runs, mean over seeds and aux settings per difficulty and column; a column with no
    finished blind run falls back to the uniform chance (`Chance.of`). Read from the blind tables' own results CSVs
    (their Text only rows are their own, never borrowed): no table is loaded, no run named."""
    from emml.report.cells import results_path
    from emml.runs.results import read_results

    values: dict = {}
    seeds: dict = {}
    for name in BLIND_TABLES:
        results = read_results(results_path(name, profile, results_root))
        if results.empty or "model" not in results:
            continue
        blind = results[results["model"] == BLIND_MODEL]
        for difficulty, group in blind.groupby("difficulty"):
            for column in COLUMNS:
                found = group[column].dropna() if column in group else []
                if len(found):
                    values[(difficulty, column)] = float(np.mean(found))
                    seeds[difficulty] = len(group)
    runs = ", ".join(f"{d}: {n} run{'s' if n != 1 else ''}" for d, n in sorted(seeds.items())) or "none yet"
    return Chance(values, f"the mean score of this profile's Text only runs ({runs})")


def paper_prior() -> Chance:
    """The paper's own Text only rows (its Tables 2 and 5), mean over aux settings per difficulty and column."""
    from emml.report.cells import paper_numbers

    pooled: dict = {}
    for name in BLIND_TABLES:
        paper = paper_numbers(name)
        for r in paper[paper["row"] == "Text only"].itertuples():
            pooled.setdefault((r.difficulty, r.metric), []).append(float(r.value))
    return Chance({k: float(np.mean(v)) for k, v in pooled.items()}, "the paper's Text only rows (Tables 2 and 5)")


def chance_text(chance: Chance, difficulties: tuple[str, ...] = ("easy", "hard", "house")) -> str:
    """'Easy: SGN test 0.20, EQA test 0.45 (measured), ...' for a page."""
    from emml.config.env_kinds import env_label

    parts = []
    for d in difficulties:
        cells = []
        for metric in COLUMNS:
            how = "" if chance.measured(metric, d) else " (uniform)"
            cells.append(f"{label(metric)} {chance.of(metric, d):.2f}{how}")
        parts.append(f"{env_label(d)}: " + ", ".join(cells))
    return "; ".join(parts)
