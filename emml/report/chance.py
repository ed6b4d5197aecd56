"""Chance from the task (issue 81, item 1): the best a model that sees no frame can score, per difficulty, task and
split, enumerated from the episode generator (emml/envs/ceiling.py): the best fixed answer per question (EQA), the
best fixed object slot per instruction (SGN), weighted as the env draws the sentences. No run is read: the Text only
row is a row like any other. The claims page (ours and the paper's own tables alike), the sample-efficiency tables
and the curves' chance lines all read it (emml/experiments/claims/evidence.py: `Chance`)."""

from __future__ import annotations

import functools
from collections.abc import Iterator, Mapping
from pathlib import Path

from emml.config.env_kinds import ENV_KINDS
from emml.config.profiles import Profile
from emml.envs.ceiling import split_ceiling
from emml.eval.metrics import BY_NAME, CHANCE_COLUMNS, label
from emml.experiments.claims.evidence import Chance

BLIND_MODEL = "text_only"
"""The model that sees no frame (the claims mark its row: its score is no evidence of having learned)."""
COLUMNS = CHANCE_COLUMNS
"""The columns chance is given for: each metric's declared `chance` (emml/eval/metrics.py)."""
SOURCE = (
    "the best fixed answer per question (EQA) and the best fixed object slot per instruction (SGN), enumerated from "
    "the episode generator (emml/envs/ceiling.py)"
)
"""What chance is, as the pages say it."""


class CeilingValues(Mapping):
    """(difficulty, chance column) → the split's blind ceiling (`split_ceiling`), for every env kind and column,
    each computed when first read (the House's enumeration takes seconds; a page about Doom never pays it)."""

    def __init__(self) -> None:
        self._keys = tuple((d, c) for d in ENV_KINDS for c in COLUMNS)

    def __getitem__(self, key) -> float:
        if key not in self._keys:
            raise KeyError(key)
        difficulty, column = key
        return split_ceiling(difficulty, BY_NAME[column].task, BY_NAME[column].split)

    def __contains__(self, key) -> bool:
        return key in self._keys  # without computing it (Mapping's own would read the value)

    def __iter__(self) -> Iterator:
        return iter(self._keys)

    def __len__(self) -> int:
        return len(self._keys)


@functools.cache
def task_ceiling() -> Chance:
    """The chance every score is held against: the best a model that sees no frame can score, per difficulty and
    column, enumerated from the episode generator; exact (no uniform floor under it)."""
    return Chance(CeilingValues(), SOURCE, exact=True)


def blind_prior(profile: Profile | None = None, results_root: str | Path | None = None) -> Chance:
    """The chance a profile's results are held against (the claims, the tables' 'leaves chance'): the task's
    ceiling (`task_ceiling`). It depends on the task only; the arguments name the results it is read for."""
    return task_ceiling()


def paper_prior() -> Chance:
    """The chance the paper's own tables are held against: the same task's ceiling (same task, same rule for both
    sides; the paper's Text only rows are a row like any other)."""
    return task_ceiling()


def chance_text(chance: Chance, difficulties: tuple[str, ...] = ("easy", "hard", "house")) -> str:
    """'Easy: SGN test 0.20, EQA test 0.56, ...' for a page ('(uniform)' where no value is given)."""
    from emml.config.env_kinds import env_label

    parts = []
    for d in difficulties:
        cells = []
        for metric in COLUMNS:
            how = "" if chance.measured(metric, d) else " (uniform)"
            cells.append(f"{label(metric)} {chance.of(metric, d):.2f}{how}")
        parts.append(f"{env_label(d)}: " + ", ".join(cells))
    return "; ".join(parts)
