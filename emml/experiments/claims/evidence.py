"""The evidence a claim of the paper rests on, and the rules that weigh it (issues 49 and 60).

A claim compares cells of a table; a cell holds one `Score` per run (seed). The comparisons (`order`, `level`,
`threshold`, `faster`, `diagnostic`, `most`) each return a `Check`; `status` turns a claim's checks into one of
STATUSES. The rules are pure functions of the numbers: the same code decides our runs (emml/report/claims.py) and
the paper's own tables (its numbers as one seed each), so a rule the paper's own table fails is seen to fail.

- Chance is what a blind model scores here (`Chance`): the Text only row of the same source, per difficulty, task
  and split (the paper's Table 2 row for the paper; ours for our runs), never below the uniform chance (each metric's
  declared `uniform`: emml/eval/metrics.py).
- A row has learned when its training split is above chance + LEAVE (`learned`: the mean over every seed the row
  has); a row with no training score (the paper's tables) is read on the cell itself. A row that learned and loses
  is contradicted; a row that did not learn says nothing against the paper (not supported at this budget).
- A gap counts when it exceeds Z (one-sided 95%) standard errors of the difference of the two rows' means. Each
  row's error is the larger of the between-seed spread (with two seeds or more: sample variance / seeds, as Welch's
  test) and the binomial error of its success rates (p(1-p)/N per seed, N its evaluation episodes); one seed:
  binomial only, and the status says 'on 1 seed'.
- A reversal of ours is 'contradicted' only when a second seed and more frames would not overturn it (issue 81:
  emml/experiments/claims/settle.py sets `Check.unsettled`); otherwise the claim's status is one of PROVISIONAL.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from emml.eval.metrics import BY_NAME
from emml.eval.metrics import metric as _metric

SUPPORTED, CONTRADICTED, INCONCLUSIVE, BUDGET, UNTESTABLE = (
    "supported",
    "contradicted",
    "not supported (within the error)",
    "not supported at this budget",
    "untestable yet",
)
ONE_SEED, CLOSING, UNKNOWN_FLAT = (
    "reversed on 1 seed",
    "reversed, still closing at this budget",
    "reversed, flatness unknown",
)
PROVISIONAL = (ONE_SEED, CLOSING, UNKNOWN_FLAT)
"""A reversal a second seed or more frames could overturn (issue 81 item 3, emml/experiments/claims/settle.py), in
the order a claim's status names them: a row on one seed with no spread to borrow that keeps it reversed; the gap
still closing over the last third of the evaluations; no curve here to say whether it is."""
STATUSES = (SUPPORTED, CONTRADICTED, *PROVISIONAL, INCONCLUSIVE, BUDGET, UNTESTABLE)
"""INCONCLUSIVE: the rows learned, and a gap is within the error; BUDGET: the row the claim puts higher has not
learned its training split (its loss says nothing against the paper at this budget); CONTRADICTED: a reversal that
is settled (`Check.unsettled` empty); PROVISIONAL: every reversal is not."""
HOLDS, REVERSED, UNCLEAR, MISSING = "holds", "reversed", "unclear", "missing"
Z = 1.645
"""A gap counts when it exceeds Z standard errors of the difference of the two means: a one-sided test at 95% (each
claim orders two rows one way). The paper's own tables pass every claim at it but aux-helps (which they fail at any
Z); at 1.96 they would fail da-best-hard-noaux and house-da-best too (EQA 0.38 vs 0.33, 0.29 vs 0.24 at 500
episodes)."""
LEAVE = 0.1
"""A score has left chance when it is above chance + LEAVE: the binomial noise of a 500 episode evaluation is about
0.02, of a 100 episode one about 0.045."""


def task_of(metric: str) -> str:
    """'sgn' or 'eqa' for a results column (sgn_test, eqa_train, sgn_transfer, ...)."""
    return _metric(metric).task


def split_of(metric: str) -> str:
    """'train' for a training-split column, else 'test' (a transfer instruction is unseen: a test split)."""
    return BY_NAME[_metric(metric).chance].split


@dataclass(frozen=True)
class Chance:
    """What a model that sees no frame scores, per (difficulty, task_split) ('sgn_test', 'eqa_train', ...)."""

    values: dict = field(default_factory=dict)
    """(difficulty, 'eqa_test') → chance there: the task's blind ceiling (emml/report/chance.py, a mapping computed
    when read) or a blind row's measured score; absent: the metric's declared uniform floor."""
    source: str = "the uniform chance"
    """Where the values come from, for the page ('the best fixed answer per question, enumerated ...')."""
    exact: bool = False
    """The values are the task's exact ceiling (emml/envs/ceiling.py), taken as they are, below the uniform floor
    too (the House's colour questions: 1/4 of four colours); False: measured scores, never below the floor (a blind
    run's noise)."""

    def of(self, metric: str, difficulty: str) -> float:
        """Chance for a results column in a difficulty: the value of the column its declaration names (if measured,
        never below its declared uniform floor); the floor where there is none."""
        declared = _metric(metric)
        value = self.values.get((difficulty, declared.chance))
        floor = declared.uniform
        if value is None:
            return floor
        return float(value) if self.exact else max(floor, float(value))

    def bar(self, metric: str, difficulty: str) -> float:
        """The score a run must exceed to have left chance: chance + LEAVE."""
        return self.of(metric, difficulty) + LEAVE

    def measured(self, metric: str, difficulty: str) -> bool:
        """Whether chance there is a value given (the ceiling, or a blind row's score), not the uniform floor."""
        return (difficulty, _metric(metric).chance) in self.values


@dataclass
class Score:
    """One run's number in a cell."""

    run: str
    seed: int
    value: float
    episodes: int
    """Episodes the number is the success rate of (a results row's eval_episodes × the instructions a transfer row
    averages); 0 for a number that is no success rate (frames, a diagnostic)."""
    frames: int
    train: float | None = None
    """The run's score on the training split of the task compared (sgn_train for an SGN cell); the paper's tables
    have none: the cell's own value stands in."""
    bar: float = -math.inf
    """`train` must exceed this for the run to have learned (chance + LEAVE of the training split); -inf for the
    blind row, whose score is the chance line itself."""
    every: int = 0
    """'faster': the largest gap between the run's evaluations in frames (a crossing is known to that resolution)."""
    metric: str = ""
    """What `value` reads: a results column (its curve is `eval/<metric>` in metrics.csv) or a diag/* key; '' for a
    crossing or the paper's tables (no curve)."""
    chance: float | None = None
    """`value` is the rate above this chance, (rate − chance) / (1 − chance) (kind 'harder', which compares two
    tasks: `above_chance`); None: the rate itself."""
    borrowed: float = 0.0
    """A between-seed variance (of the rate) borrowed from the nearest cell of the same row with two seeds or more,
    for a row of one seed (`settle`); 0: none found. Read only when a reversal is weighed for being settled."""
    borrowed_from: str = ""
    """Where `borrowed` comes from, for the page ('Text only, Easy · Aux: 2 seeds')."""

    @property
    def rate(self) -> float:
        """The success rate itself (`value` undone of `chance`)."""
        return self.value if self.chance is None else self.chance + self.value * (1 - self.chance)

    @property
    def scale(self) -> float:
        """What a rate's deviation is multiplied by in `value`: 1 / (1 − chance), or 1."""
        return 1.0 if self.chance is None else 1.0 / (1.0 - self.chance)


def above_chance(scores: list[Score], chance: float) -> list[Score]:
    """Each score as its rate above ``chance``: (rate − chance) / (1 − chance), 0 at chance and 1 at a perfect score
    (issue 81 item 4: a rule that compares two tasks compares how far each is above its own task's chance); the
    training score and its bar stay as they are ('learned' is read on the training split's own rate)."""
    if not 0 <= chance < 1:
        raise ValueError(f"chance={chance!r}: must be in [0, 1) to measure a rate above it")
    return [replace(s, value=(s.value - chance) / (1 - chance), chance=chance) for s in scores]


def learned(scores: list[Score]) -> bool:
    """Whether the row learned its training split: the mean training score of the seeds that have one above the
    bar; a run without a training score is left out, not averaged in (issue 85 item 4), and a row none of whose runs
    has one has not shown it learned. The paper's tables, which give no training score, pass the cell's own value
    as it (emml/report/claims.py, `paper_evidence`)."""
    known = [s for s in scores if s.train is not None]
    if not known:
        return False
    return float(np.mean([s.train for s in known])) > max(s.bar for s in known)


@dataclass
class Check:
    """One comparison a claim makes: two cells, or a cell against a threshold."""

    where: str
    """The cells read, e.g. 'SGN test, Easy · Aux' (a row's name for one of 'harder''s per-row comparisons)."""
    compared: str
    """The comparison itself, e.g. 'Dual-Attention > Text only' (the claims' phrase names it after the metric)."""
    outcome: str
    """HOLDS, REVERSED (the opposite holds by the same rule), UNCLEAR or MISSING."""
    detail: str
    """The numbers: each seed's, the gap and its standard error."""
    chance: bool = False
    """The row the claim puts higher (the reference of 'level') has not learned its training split."""
    seeds: int = 0
    """The fewest seeds of the rows compared."""
    high: list[Score] = field(default_factory=list)
    """The scores of the row the claim puts higher (the reference of 'level'), every seed."""
    numbers: str = ""
    """The means compared, short: '0.38 vs 0.45'."""
    setting: str = ""
    metric: str = ""
    subject: str = ""
    """The row the claim puts higher."""
    rows: tuple[str, ...] = ()
    """The table rows the comparison reads (the page shows them when it decides against the claim)."""
    low: list[Score] = field(default_factory=list)
    """The scores of the other row (the lower one of 'order', the row compared with the reference of 'level'); []
    for a threshold."""
    against: float | None = None
    """How far the means lie beyond the rule's boundary against the claim: −gap ('order'), |difference| − margin
    ('level'), value − mean ('threshold'); REVERSED is `against` > Z × the standard error. None: a rule without an
    error term ('faster', 'diagnostic', 'most')."""
    orient: float = 1.0
    """The sign that turns high − low (per evaluation point) into a gap that grows towards the claim: −1 for a
    'level' row below its reference (its difference closes as it rises), else +1."""
    floor: float | None = None
    """'threshold': the value the row's curve is held against (its low side is this constant)."""
    parts: list[Check] = field(default_factory=list)
    """'most': the rows' own comparisons it counts."""
    unsettled: str = ""
    """For a REVERSED check, the provisional status that holds it back from 'contradicted' (one of PROVISIONAL:
    emml/experiments/claims/settle.py); '' when it is settled or was never weighed (the paper's own tables)."""
    settlement: str = ""
    """Why it is settled or not, for the page: the seeds, a borrowed spread, the gap's slope over the last third of
    the evaluations with its interval."""
    settle_by: list[str] = field(default_factory=list)
    """What would settle it: the missing seeds' runs ('table2/text_only-easy-aux-s1-quick') or 'more frames'."""

    @property
    def what(self) -> str:
        """E.g. 'SGN test, Easy · Aux: Dual-Attention > Text only'."""
        return f"{self.where}: {self.compared}"

    def tag(self, setting: str, metric: str, subject: str, rows: tuple[str, ...]) -> Check:
        """The check with its setting, metric label, higher row and the rows it reads named (the page groups by
        setting)."""
        self.setting, self.metric, self.subject, self.rows = setting, metric, subject, rows
        return self


def mean(scores: list[Score]) -> float:
    return float(np.mean([s.value for s in scores]))


def variance_of_mean(scores: list[Score], borrow: bool = False) -> float:
    """The squared standard error of a row's mean: the larger of the between-seed sample variance and the mean
    binomial variance of one seed's rate, over the seeds (one seed: binomial only; with ``borrow``, its `borrowed`
    between-seed variance in the spread's place). A value above chance (`Score.chance`) has both scaled by
    1 / (1 − chance)²."""
    n = len(scores)
    binomial = float(np.mean([s.rate * (1 - s.rate) / max(s.episodes, 1) * s.scale**2 for s in scores]))
    if n > 1:
        spread = float(np.var([s.value for s in scores], ddof=1))
    else:
        spread = scores[0].borrowed * scores[0].scale ** 2 if borrow else 0.0
    return max(spread, binomial) / n


def gap_error(a: list[Score], b: list[Score], borrow: bool = False) -> float:
    """The standard error of mean(a) - mean(b), the rows independent (Welch); a row may be [] (a threshold's
    constant). ``borrow``: one-seed rows read their borrowed spread (`variance_of_mean`)."""
    return math.sqrt(sum(variance_of_mean(r, borrow) for r in (a, b) if r))


def seeds_text(scores: list[Score]) -> str:
    return " · ".join(f"{s.value:.3f} (s{s.seed})" for s in scores)


def _error_text(*rows: list[Score]) -> str:
    return "between seeds and binomial" if any(len(r) > 1 for r in rows) else "binomial, 1 seed"


def _missing(where: str, compared: str, hi: list[Score], lo: list[Score]) -> Check:
    """A comparison with a cell still empty; `chance` when the row the claim puts higher is there and unlearned."""
    if not hi:
        return Check(
            where, compared, MISSING, "no run yet in " + ("either cell" if not lo else "the higher row's cell")
        )
    unlearned = not learned(hi)
    detail = f"no run yet in the lower row's cell; the higher row {seeds_text(hi)}"
    if unlearned:
        detail += ", which has not learned its training split"
    return Check(where, compared, MISSING, detail, unlearned, len(hi), hi)


def order(where: str, compared: str, hi: list[Score], lo: list[Score]) -> Check:
    """Whether `hi` is above `lo` (HOLDS), below (REVERSED) or neither: the gap of the means over every seed each
    row has, against Z standard errors (`gap_error`)."""
    if not hi or not lo:
        return _missing(where, compared, hi, lo)
    gap, se = mean(hi) - mean(lo), gap_error(hi, lo)
    outcome = HOLDS if gap > Z * se else REVERSED if -gap > Z * se else UNCLEAR
    unlearned = not learned(hi)
    detail = (
        f"{seeds_text(hi)} against {seeds_text(lo)}: gap {gap:+.3f}, standard error {se:.3f} ({_error_text(hi, lo)})"
    )
    if unlearned:
        detail += "; the higher row has not learned its training split"
    return Check(
        where,
        compared,
        outcome,
        detail,
        unlearned,
        min(len(hi), len(lo)),
        hi,
        f"{mean(hi):.2f} vs {mean(lo):.2f}",
        low=lo,
        against=-gap,
    )


def level(where: str, compared: str, row: list[Score], ref: list[Score], margin: float) -> Check:
    """Whether `row` is within `margin` of `ref` (HOLDS), beyond it by more than Z standard errors (REVERSED) or
    neither; two unlearned rows are level trivially, so an unlearned reference never holds."""
    if not row or not ref:
        return _missing(where, compared, ref, row)
    diff, se = mean(row) - mean(ref), gap_error(row, ref)
    unlearned = not learned(ref)
    if abs(diff) <= margin and not unlearned:
        outcome = HOLDS
    elif abs(diff) - margin > Z * se:
        outcome = REVERSED
    else:
        outcome = UNCLEAR
    detail = (
        f"{seeds_text(row)} against {seeds_text(ref)}: difference {diff:+.3f} (margin {margin:g}), standard error "
        f"{se:.3f} ({_error_text(row, ref)})"
    )
    if unlearned:
        detail += "; the reference row has not learned its training split"
    return Check(
        where,
        compared,
        outcome,
        detail,
        unlearned,
        min(len(row), len(ref)),
        ref,
        f"{mean(row):.2f} vs {mean(ref):.2f}",
        low=row,
        against=abs(diff) - margin,
        orient=-1.0 if diff < 0 else 1.0,
    )


def threshold(where: str, compared: str, row: list[Score], value: float) -> Check:
    """Whether the row's mean is at or above `value` (HOLDS), below it by more than Z standard errors (REVERSED) or
    neither."""
    if not row:
        return Check(where, compared, MISSING, "no run yet")
    m, se = mean(row), math.sqrt(variance_of_mean(row))
    outcome = HOLDS if m >= value else REVERSED if value - m > Z * se else UNCLEAR
    unlearned = not learned(row)
    detail = f"{seeds_text(row)}: mean {m:.3f} against {value:g}, standard error {se:.3f} ({_error_text(row)})"
    if unlearned:
        detail += "; the row has not learned its training split"
    return Check(
        where,
        compared,
        outcome,
        detail,
        unlearned,
        len(row),
        row,
        f"{m:.2f} vs {value:g}",
        against=value - m,
        floor=value,
    )


def frames_text(frames: int | None, last: int) -> str:
    """'0.30M', or '>1.50M' (not by the last evaluation at `last` frames)."""
    return f">{last / 1e6:.2f}M" if frames is None else f"{frames / 1e6:.2f}M"


def frames_list(scores: list[Score]) -> str:
    """Each run's crossing, 'frames (seed)'."""
    return " · ".join(
        f"{frames_text(None if math.isinf(s.value) else int(s.value), s.frames)} (s{s.seed})" for s in scores
    )


def _median_frames(scores: list[Score]) -> str:
    v = float(np.median([s.value for s in scores]))
    return frames_text(None if math.isinf(v) else int(v), max(s.frames for s in scores))


def faster(where: str, compared: str, fast: list[Score], slow: list[Score]) -> Check:
    """Whether `fast` crosses its mark more than one evaluation gap before `slow` in every seed both have (HOLDS),
    `slow` first by as much in every seed (REVERSED) or neither. A value is the frames at the crossing (inf: never by
    the run's last evaluation); the gap is the larger of the two runs' largest gaps between evaluations (a crossing
    is known to that resolution). `chance`: the faster row never crosses in the seeds compared."""
    if not fast or not slow:
        which = "either cell" if not fast and not slow else "one cell"
        return Check(where, compared, MISSING, f"no run with a metrics.csv here in {which}")
    common = sorted({s.seed for s in fast} & {s.seed for s in slow})
    f = [s for s in fast if s.seed in common]
    s_ = [s for s in slow if s.seed in common]
    if not f:
        return Check(where, compared, MISSING, "no seed in common")
    apart = [max(a.every, b.every) for a, b in zip(f, s_)]
    if all(b.value - a.value > gap for a, b, gap in zip(f, s_, apart)):
        outcome = HOLDS
    elif all(a.value - b.value > gap for a, b, gap in zip(f, s_, apart)):
        outcome = REVERSED
    else:
        outcome = UNCLEAR
    never = all(math.isinf(a.value) for a in f)
    detail = f"{frames_list(f)} against {frames_list(s_)} (evaluations up to {max(apart):,} frames apart)"
    if never:
        detail += "; the faster row never crosses by its last evaluation"
    numbers = f"{_median_frames(f)} vs {_median_frames(s_)}"
    return Check(where, compared, outcome, detail, never, len(f), fast, numbers, low=slow)


def diagnostic(where: str, compared: str, row: list[Score], value: float) -> Check:
    """Whether the row's mean diagnostic is at or above `value` (HOLDS), every seed below (REVERSED) or neither;
    `chance`: the row has not learned its training split (its figure says nothing yet)."""
    if not row:
        return Check(where, compared, MISSING, "no run with a metrics.csv here")
    m = mean(row)
    outcome = HOLDS if m >= value else REVERSED if all(s.value < value for s in row) else UNCLEAR
    unlearned = not learned(row)
    detail = " · ".join(f"{s.value:.3f} (s{s.seed}, at {s.frames:,} frames)" for s in row) + f": mean {m:.3f}"
    detail += f" against {value:.3g}"
    if unlearned:
        detail += "; the run has not learned its training split"
    return Check(where, compared, outcome, detail, unlearned, len(row), row, f"{m:.2f} vs {value:.2g}", floor=value)


def most(where: str, compared: str, checks: list[Check], unlearned_rows: int) -> Check:
    """'harder': the rows' own comparisons (`order`, one per row) taken together, every row counted (the paper's
    "most models" counts every row): HOLDS when more than half hold, REVERSED when more than half are reversed,
    MISSING while a row has no run; `chance` when more than half of the rows have not learned their training split
    (`unlearned_rows` of them)."""
    absent = [row for c in checks if c.outcome == MISSING for row in c.rows]
    if absent:
        return Check(where, compared, MISSING, f"no run yet for {', '.join(absent)}")
    held = sum(c.outcome == HOLDS for c in checks)
    reversed_ = sum(c.outcome == REVERSED for c in checks)
    outcome = HOLDS if held * 2 > len(checks) else REVERSED if reversed_ * 2 > len(checks) else UNCLEAR
    detail = "; ".join(f"{c.what}: {c.outcome}, {c.numbers}" for c in checks)
    detail += f" ({unlearned_rows} of {len(checks)} rows have not learned their training split)"
    seeds = min(c.seeds for c in checks)
    return Check(
        where,
        compared,
        outcome,
        detail,
        unlearned_rows * 2 > len(checks),
        seeds,
        [],
        f"in {held} of {len(checks)} rows",
        parts=list(checks),
    )


def status(checks: list[Check], single_subject: bool = True) -> str:
    """The claim's status from its comparisons: contradicted when a row that learned loses by the rule and the
    reversal is settled (`Check.unsettled` empty: emml/experiments/claims/settle.py); else, while such a reversal
    is not settled, the first of PROVISIONAL any of them has; not supported at this budget when a row the claim puts
    higher has not learned and does not win (with `single_subject`, the claim's one subject row unlearned anywhere,
    cells missing or not); untestable while a cell is empty; supported when every comparison holds; otherwise not
    supported within the error (the rows learned, a gap is inside Z standard errors)."""
    outcomes = [c.outcome for c in checks]
    reversed_ = [c for c in checks if c.outcome == REVERSED and not c.chance]
    if any(not c.unsettled for c in reversed_):
        return CONTRADICTED
    if reversed_:
        return next(p for p in PROVISIONAL if any(c.unsettled == p for c in reversed_))
    if any(
        c.chance and (c.outcome in (REVERSED, UNCLEAR) or (single_subject and c.outcome == MISSING)) for c in checks
    ):
        return BUDGET
    if MISSING in outcomes or not outcomes:
        return UNTESTABLE
    if all(o == HOLDS for o in outcomes):
        return SUPPORTED
    return INCONCLUSIVE
