"""The kinds of claim (reproduce/claims.toml `kind`): each one object that says which fields it needs, which rows
and cells it reads, how it reads a run's number (`Kind.read`: its results row, the crossing of its evaluation curve,
a diag/* figure), its rule as the claims page states it, and how it turns the cells' scores into comparisons
(emml/experiments/claims/evidence.py). The page asks the kind; adding a kind is one class here, its data and tests.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import Protocol

from emml.experiments.claims.evidence import (
    MISSING,
    Chance,
    Check,
    Score,
    above_chance,
    diagnostic,
    faster,
    frames_text,
    learned,
    level,
    mean,
    most,
    order,
    threshold,
)

Get = Callable[[str, str, bool, str], list[Score]]
"""(row, difficulty, aux, metric) → the scores of that cell (every seed found)."""
MARK_LABELS = {"chance": "leaves chance", "0.5": "reaches 0.5", "0.9": "reaches 0.9"}


class RunReading(Protocol):
    """One run of a claim's cell as the claims page reads it (emml/report/claims.py): each way a kind may read its
    number, None when the run has none here."""

    def result(self, metric: str) -> Score | None:
        """Its results row's number of ``metric`` (a training column: that column of the same row)."""

    def crossing(self, metric: str, mark: str) -> Score | None:
        """The frames at which its evaluation curve of ``metric`` first crosses ``mark`` (inf: not by its last
        evaluation); None when its curve cannot rule out a crossing after it."""

    def last(self, key: str) -> Score | None:
        """The value of curve key ``key`` at its last evaluation."""


def setting_text(difficulty: str, aux: bool | None) -> str:
    from emml.config.env_kinds import env_label

    return env_label(difficulty) if aux is None else f"{env_label(difficulty)} · {'Aux' if aux else 'No Aux'}"


def metric_text(metric: str) -> str:
    from emml.eval.metrics import label

    return label(metric)


class Kind:
    """What every kind answers; the defaults suit the kinds that compare rows cell by cell."""

    name = ""
    needs: tuple[str, ...] = ("metrics",)
    """The claim fields this kind requires (reproduce/claims.toml)."""
    rule = ""
    """The rule as the claims page states it."""
    single_subject = True
    """The claim puts one row higher everywhere: that row unlearned leaves the claim unsupported at this budget even
    while other cells are missing."""
    reads = "results"
    """What a run's number is: 'results' (its results row), 'crossing' (the frames at which its evaluation curve
    crosses the claim's mark: `mark` allowed, any curve metric) or 'figure' (a diag/* key at its last evaluation:
    `key` and `relative` allowed)."""
    one_row = False
    """The claim names its one row as `row` (every other row of the table is compared with it)."""
    metric_count: int | None = None
    """How many metrics the claim must name (None: any)."""

    @property
    def curve(self) -> bool:
        """Reads the runs' curves (the greedy evaluation curve or a diag/* figure), not their results rows."""
        return self.reads != "results"

    @property
    def borrows(self) -> bool:
        """A one-seed cell's score borrows the between-seed spread of its row's nearest cell with more seeds, and a
        warm-up cell is shown beside its paper-literal run: numbers read from results rows (the kinds that read a
        curve have neither)."""
        return not self.curve

    def read(self, claim, metric: str, run: RunReading) -> Score | None:
        """The run's number for the claim's ``metric``, read as this kind reads it (`reads`); None: none here (the
        cell's run is missing, `missing`)."""
        return run.result(metric)

    def missing(self, name: str, metric: str) -> str:
        """How the evidence names a run whose number `read` found none of."""
        return f"{name} (no {metric} in its results row)"

    def shown(self, score: Score) -> str:
        """A score as the evidence prints it."""
        return f"{score.value:.3f}"

    def involved(self, claim, table) -> set[str]:
        """The rows whose scores the claim reads."""
        return {*claim.rows, *([claim.than] if claim.than else [])}

    def wheres(self, claim) -> list[dict]:
        """The column selections whose cells are read (RunSpec fields: difficulty, aux)."""
        return [claim.where]

    def metric_label(self, claim, metric: str) -> str:
        """How the evidence names what it reads."""
        return metric_text(metric)

    def checks(self, claim, table, keys: list[tuple], get: Get, chance: Chance | None = None) -> list[Check]:
        """The comparisons, one per (difficulty, aux, metric) key of the claim's cells (``chance``: what the scores
        are held against, for a kind that compares tasks; the others read it through each score's bar)."""
        out = []
        for d, a, m in keys:
            out += [
                c.tag(setting_text(d, a), metric_text(m), rows[0], rows)
                for c, rows in self.compare(claim, table, d, a, m, get)
            ]
        return out

    def compare(self, claim, table, d: str, a: bool, m: str, get: Get) -> list[tuple[Check, tuple[str, ...]]]:
        """The cell's comparisons, each with the rows it reads, the row the claim puts higher first."""
        raise NotImplementedError


def _where(d: str, a: bool, m: str) -> str:
    return f"{metric_text(m)}, {setting_text(d, a)}"


class Best(Kind):
    name = "best"
    needs = ("row", "metrics")
    one_row = True
    rule = (
        "**best**: the claim's row above every other row of the table in each cell, by the ordering rule ('the gap of "
        "the means beyond the error')."
    )

    def involved(self, claim, table) -> set[str]:
        return {r.label for r in table.rows}

    def compare(self, claim, table, d, a, m, get):
        top = claim.rows[0]
        return [
            (order(_where(d, a, m), f"{top} > {other}", get(top, d, a, m), get(other, d, a, m)), (top, other))
            for other in (r.label for r in table.rows if r.label != top)
        ]


class Below(Kind):
    name = "below"
    needs = ("rows", "than", "metrics")
    rule = "**below**: each of the claim's rows below the reference row in each cell, by the ordering rule."

    def compare(self, claim, table, d, a, m, get):
        return [
            (
                order(_where(d, a, m), f"{claim.than} > {row}", get(claim.than, d, a, m), get(row, d, a, m)),
                (claim.than, row),
            )
            for row in claim.rows
        ]


class Level(Kind):
    name = "level"
    needs = ("rows", "than", "margin", "metrics")
    rule = (
        "**level**: each row's mean within the claim's margin of the reference row's, the reference having learned; "
        "reversed when the difference exceeds the margin by more than the error."
    )

    def compare(self, claim, table, d, a, m, get):
        return [
            (
                level(
                    _where(d, a, m),
                    f"{row} level with {claim.than}",
                    get(row, d, a, m),
                    get(claim.than, d, a, m),
                    claim.margin,
                ),
                (claim.than, row),
            )
            for row in claim.rows
        ]


class AtLeast(Kind):
    name = "at_least"
    needs = ("value", "metrics")
    rule = "**at_least**: each row's mean at or above the claim's value; reversed when below it by more than the error."

    def compare(self, claim, table, d, a, m, get):
        return [
            (threshold(_where(d, a, m), f"{row} ≥ {claim.value:g}", get(row, d, a, m), claim.value), (row,))
            for row in claim.rows
        ]


class AuxHelps(Kind):
    name = "aux_helps"
    rule = "**aux_helps**: per row and difficulty, the row with aux above the same row without, by the ordering rule."
    single_subject = False

    def checks(self, claim, table, keys, get, chance=None):
        out = []
        for row in claim.rows:
            for d, m in dict.fromkeys((d, m) for (d, _, m) in keys):
                where = f"{metric_text(m)}, {setting_text(d, None)}"
                check = order(where, f"{row} Aux > No Aux", get(row, d, True, m), get(row, d, False, m))
                out.append(check.tag(setting_text(d, None), metric_text(m), f"{row} Aux", (row,)))
        return out


class Harder(Kind):
    name = "harder"
    metric_count = 2
    rule = (
        "**harder** ('EQA is more challenging than SGN'): per setting, each row's first metric against its second "
        "on the same runs, each read above its own task's chance, (score − chance) / (1 − chance) (a raw EQA rate "
        "and a raw SGN rate are not comparable: chance differs), by the ordering rule; it holds where more than half "
        "of all the rows hold (the paper: 'most models'), is reversed where more than half are reversed, and waits "
        "while a row has no run; it is excused (not supported at this budget) only when more than half of the rows "
        "have not learned their training split of the task the claim puts higher."
    )

    def involved(self, claim, table) -> set[str]:
        return set(claim.rows)

    def checks(self, claim, table, keys, get, chance=None):
        hard, easy = claim.metrics
        chance = chance if chance is not None else Chance()

        def above(row: str, d: str, a: bool, m: str) -> list[Score]:
            return above_chance(get(row, d, a, m), chance.of(m, d))

        out = []
        for d, a in dict.fromkeys((d, a) for (d, a, _) in keys):
            compared = f"{metric_text(easy)} > {metric_text(hard)}, above chance"
            per_row = [  # each row's own comparison, read by `most` (no setting of its own)
                replace(order(row, compared, above(row, d, a, easy), above(row, d, a, hard)), rows=(row,))
                for row in claim.rows
            ]
            unlearned = sum(not learned(get(row, d, a, easy)) for row in claim.rows if get(row, d, a, easy))
            check = most(setting_text(d, a), f"{metric_text(hard)} below {metric_text(easy)}", per_row, unlearned)
            out.append(check.tag(setting_text(d, a), "", "most rows", ()))  # its comparison names both metrics
        return out


class Faster(Kind):
    name = "faster"
    needs = ("rows", "than", "metrics")
    reads = "crossing"
    rule = (
        "**faster** (the speed claims): from each run's greedy evaluation curve (metrics.csv), the frames at which it "
        "first crosses the claim's mark (leaves chance: above the blind prior + the margin; or reaches 0.5 / 0.9); it "
        "holds when the faster row crosses first by more than the larger gap between the two runs' evaluations, in "
        "every seed both rows have (a crossing is known only to that gap; a run that never crosses counts as "
        "slowest), is reversed when the other row crosses first by as much in every seed, and is excused when the "
        "faster row never crosses."
    )

    def metric_label(self, claim, metric):
        return f"{metric_text(metric)}: frames until it {MARK_LABELS[claim.mark]}"

    def read(self, claim, metric, run):
        return run.crossing(metric, claim.mark)

    def missing(self, name, metric):
        return f"{name} (no complete metrics.csv here)"

    def shown(self, score):
        return frames_text(None if math.isinf(score.value) else int(score.value), score.frames)

    def compare(self, claim, table, d, a, m, get):
        return [
            (
                faster(
                    _where(d, a, m),
                    f"{claim.than} {MARK_LABELS[claim.mark]} before {row}",
                    get(claim.than, d, a, m),
                    get(row, d, a, m),
                ),
                (claim.than, row),
            )
            for row in claim.rows
        ]


class Diagnostic(Kind):
    name = "diagnostic"
    needs = ("rows", "key", "value")
    reads = "figure"
    rule = (
        "**diagnostic**: a `diag/*` figure of `emml diagnose`, logged at every evaluation, read at each run's last; "
        "holds when the row's mean is at or above the claim's value (with `relative`: the value times the same row's "
        "mean in the reference setting, e.g. the Aux run's own), reversed when every seed is below it while the row "
        "has learned its training split; a run with no metrics.csv here (trained elsewhere) is a missing cell."
    )

    def wheres(self, claim):
        return [claim.where] + ([{**claim.where, **claim.relative}] if claim.relative else [])

    def metric_label(self, claim, metric):
        return claim.key

    def read(self, claim, metric, run):
        return run.last(claim.key)

    def missing(self, name, metric):
        return f"{name} (no complete metrics.csv here)"

    def checks(self, claim, table, keys, get, chance=None):
        out = []
        for d, a, m in keys:
            if any(claim.where.get(k) not in (None, v) for k, v in (("difficulty", d), ("aux", a))):
                continue  # a reference setting's cell (`relative`): read by the comparison below
            for row in claim.rows:
                where, value, compared = f"{setting_text(d, a)}, {claim.key}", claim.value, f"{row} ≥ {claim.value:g}"
                if claim.relative:
                    ref = get(row, claim.relative.get("difficulty", d), claim.relative.get("aux", a), m)
                    ref_text = setting_text(claim.relative.get("difficulty", d), claim.relative.get("aux", a))
                    if not ref:
                        out.append(
                            Check(where, compared, MISSING, f"no run with a metrics.csv here in {ref_text}").tag(
                                setting_text(d, a), claim.key, row, (row,)
                            )
                        )
                        continue
                    value = claim.value * mean(ref)
                    compared = f"{row} ≥ {claim.value:g} × its {ref_text} run's {mean(ref):.2f}"
                out.append(
                    diagnostic(where, compared, get(row, d, a, m), value).tag(
                        setting_text(d, a), claim.key, row, (row,)
                    )
                )
        return out


KINDS: dict[str, Kind] = {
    k.name: k for k in (Best(), Below(), Level(), AtLeast(), AuxHelps(), Faster(), Diagnostic(), Harder())
}
"""Every kind by its name in reproduce/claims.toml."""
