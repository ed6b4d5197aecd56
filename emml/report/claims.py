"""The claims page (issue 49): each claim of reproduce/claims.toml (emml/experiments/claims.py) decided from a
profile's results, with the numbers per row and seed that decide it, the runs still missing and, where the campaign
knows them, what they cost.

A claim is one of STATUSES. The cells are the table pages' (emml/report/tables.py: `table_results`, `build_cells`),
so a claim reads exactly the numbers its table shows. The rules (`RULES`, stated on the page):

- an ordering ('best', 'below', 'aux_helps') holds in a cell when the higher row is above the lower in every seed
  both rows have, and the gap of their means exceeds the binomial standard error of that gap at the evaluation's
  episode count (each results row's `eval_episodes`);
- 'level': the two means within `margin`; 'at_least': every row's mean at or above `value`;
- a row at chance (its mean within `LEAVE` of the task's chance, `CHANCE`) has not learned at this budget: what it
  loses says nothing against the paper, and two rows at chance are level trivially;
- 'faster' (the speed claims) reads each run's greedy evaluation curve in its metrics.csv
  (emml/report/efficiency.py): the faster row crosses the mark in fewer frames in every seed both rows have;
  'diagnostic' reads a `diag/*` figure at each run's last evaluation (the same file);
- 'harder': per setting, each row's two metrics ordered as above, the claim holding in a setting where more than half
  of the rows hold (the paper's "most models").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from emml.config.profiles import Profile, resolve_profile
from emml.report.efficiency import CHANCE, LEAVE, MARK_LABELS, frames_text

SUPPORTED, CONTRADICTED, BUDGET, UNTESTABLE = (
    "supported",
    "contradicted",
    "not supported at this budget",
    "untestable yet",
)
STATUSES = (SUPPORTED, CONTRADICTED, BUDGET, UNTESTABLE)
Z = 1.0
"""A gap counts when it exceeds Z binomial standard errors of the difference of the two means."""
SEEDS_ENOUGH = 3
"""Fewer seeds than this: the decision says on how many it rests."""
HOLDS, REVERSED, UNCLEAR, MISSING = "holds", "reversed", "unclear", "missing"


@dataclass
class Score:
    """One run's number in a cell."""

    run: str
    seed: int
    value: float
    episodes: int
    """Episodes the number is the success rate of (the results row's eval_episodes × the instructions a transfer
    row averages)."""
    frames: int
    learned: bool = True
    """'diagnostic': whether the run learned its training split (sgn_train or eqa_train above chance)."""
    every: int = 0
    """'faster': the run's evaluation interval in frames (a crossing is known to that resolution)."""


@dataclass
class Check:
    """One comparison a claim makes: two cells, or a cell against a threshold."""

    what: str
    """E.g. 'SGN test, Easy · Aux: Dual-Attention > Text only'."""
    outcome: str
    """HOLDS, REVERSED (the opposite holds by the same rule), UNCLEAR or MISSING."""
    detail: str
    """The numbers: each seed's, the gap and its standard error."""
    chance: bool = False
    """The row the claim puts higher (the reference of 'level') is at chance in the seeds compared."""
    seeds: int = 0
    """Seeds the comparison read."""
    high: list[Score] = field(default_factory=list)
    """The scores of the row the claim puts higher (the reference of 'level'), every seed."""
    numbers: str = ""
    """The means compared, short: '0.38 vs 0.45'."""
    setting: str = ""
    metric: str = ""
    subject: str = ""
    """The row the claim puts higher."""


@dataclass
class Decision:
    """A claim decided from one profile's results."""

    id: str
    text: str
    source: str
    kind: str
    table: str
    profile: str
    status: str
    phrase: str
    """The evidence in a phrase (the page's top block)."""
    checks: list[Check] = field(default_factory=list)
    evidence: list[dict] = field(default_factory=list)
    """One line per row and cell: row, setting, metric, each seed's value."""
    missing: list[str] = field(default_factory=list)
    """Declared runs of the claim's cells with no results row."""
    frames: list[int] = field(default_factory=list)
    seeds: int = 0
    """The fewest seeds any comparison present read."""
    costs: list[str] = field(default_factory=list)
    """What the missing runs cost, from the campaign (emml.experiments.campaign.status), when it knows them."""

    @property
    def label(self) -> str:
        """The status, with the seeds it rests on when fewer than SEEDS_ENOUGH."""
        if self.status == UNTESTABLE or not self.seeds or self.seeds >= SEEDS_ENOUGH:
            return self.status
        return f"{self.status} (on {self.seeds} seed{'s' if self.seeds != 1 else ''})"


RULES = [
    "**supported**: every comparison of the claim holds. 'best' / 'below' (and 'aux_helps', per row with both "
    "settings): the higher row is above the lower one in every seed both have, and the gap of their means exceeds "
    f"{Z:g} binomial standard error of that gap, sqrt(Σ p(1−p)/N)/k per row over its k seeds with N the evaluation's "
    "episodes (a results row's eval_episodes; a transfer row: times its instructions). 'level': the two means "
    "within the claim's margin, the reference row not at chance. 'at_least': every row's mean at or above the "
    "claim's value.",
    "**contradicted**: some comparison is reversed by the same rule (the lower row above in every seed, the gap "
    "beyond the standard error; 'level': the difference beyond the margin in every seed and by more than the "
    "standard error; 'at_least': the mean below the value by more than the standard error, every seed below) while "
    "the row the claim puts higher has left chance: it learned, and still loses.",
    "**not supported at this budget**: the cells are there, but the ordering holds in no seed, or only in some, or "
    "within the standard error; or the row the claim puts higher is at chance (it has not learned with the "
    "profile's frames, so its loss says nothing against the paper, and two rows at chance are level trivially).",
    "**untestable yet**: a cell the claim compares has no finished run (the missing runs are listed); numbers "
    "already there are shown.",
    "**faster** (the speed claims): from each run's greedy evaluation curve (metrics.csv, every `eval_every` frames), "
    "the frames at which it first crosses the claim's mark (leaves chance: above chance + the margin below; or "
    "reaches 0.5 / 0.9); it holds when the row the claim puts faster crosses more than one evaluation interval first "
    "in every seed both rows have (a crossing is known to that resolution; a run that never crosses counts as "
    "slowest), is reversed when the other row crosses first by as much in every seed, and is "
    "at chance when the faster row never crosses. **diagnostic**: a `diag/*` figure of `emml diagnose`, logged at "
    "every evaluation, read at each run's last; holds when the mean is at or above the claim's value, reversed when "
    "every seed is below it while the run has learned its training split (sgn_train or eqa_train above chance); a "
    "run with no metrics.csv here (trained elsewhere) is a missing cell.",
    "**harder** ('EQA is more challenging than SGN'): per setting, each row's first metric against its second, "
    "ordered by the rule above on the same runs; it holds where more than half of the rows hold (the paper: 'most "
    "models'), is reversed where more than half are reversed, and waits while a row has no run.",
    f"Chance: SGN {CHANCE['sgn']:.2f} (one of five objects); EQA {CHANCE['eqa']:.2f} (the paper's Text only row, which "
    f"sees no frame, scores 0.33 in every column); a row is at chance when its mean is at most chance + {LEAVE:.2f}. "
    "Comparisons pair seeds: a row with more seeds than the other is compared on the seeds both have (its other "
    "seeds are shown). Fewer than 3 seeds: the status says on how many it rests.",
]


def _chance(metric: str) -> float:
    return CHANCE["eqa" if metric.startswith("eqa") else "sgn"]


def _se(scores: list[Score]) -> float:
    """Binomial standard error of the mean of the scores (each a success rate over its episodes)."""
    var = sum(s.value * (1 - s.value) / max(s.episodes, 1) for s in scores)
    return math.sqrt(var) / len(scores)


def _seeds(scores: list[Score]) -> str:
    return " · ".join(f"{s.value:.3f} (s{s.seed})" for s in scores)


def _pair(hi: list[Score], lo: list[Score]) -> tuple[list[Score], list[Score]]:
    common = sorted({s.seed for s in hi} & {s.seed for s in lo})
    return [s for s in hi if s.seed in common], [s for s in lo if s.seed in common]


def _paired_gap(a: list[Score], b: list[Score]) -> tuple[list[float], float, float]:
    """On seeds already paired (`_pair`): the per-seed differences a - b, their mean and its binomial standard error."""
    diffs = [x.value - y.value for x, y in zip(a, b)]
    return diffs, float(np.mean(diffs)), math.sqrt(_se(a) ** 2 + _se(b) ** 2)


def _at_chance(scores: list[Score], metric: str) -> bool:
    """Whether the scores' mean is within LEAVE of the metric's chance: the row has not learned at this budget."""
    return _mean(scores) <= _chance(metric) + LEAVE


def _chance_note(metric: str) -> str:
    return f"({_chance(metric):.2f} + {LEAVE:.2f})"


def order(what: str, hi: list[Score], lo: list[Score], metric: str) -> Check:
    """Whether `hi` is above `lo` (HOLDS), below (REVERSED) or neither, by the rule of RULES."""
    if not hi or not lo:
        return _missing(what, hi, lo, metric)
    h, lw = _pair(hi, lo)
    if not h:
        return Check(what, MISSING, f"no seed in common ({_seeds(hi)} against {_seeds(lo)})")
    diffs, gap, se = _paired_gap(h, lw)
    if all(d > 0 for d in diffs) and gap > Z * se:
        outcome = HOLDS
    elif all(d < 0 for d in diffs) and -gap > Z * se:
        outcome = REVERSED
    else:
        outcome = UNCLEAR
    at_chance = _at_chance(h, metric)
    detail = f"{_seeds(h)} against {_seeds(lw)}: gap {gap:+.3f}, standard error {se:.3f}"
    if at_chance:
        detail += f"; the higher row at chance {_chance_note(metric)}"
    return Check(what, outcome, detail, at_chance, len(h), hi, f"{_mean(h):.2f} vs {_mean(lw):.2f}")


def _missing(what: str, hi: list[Score], lo: list[Score], metric: str) -> Check:
    """A comparison with a cell still empty; `chance` when the row the claim puts higher is there and at chance."""
    if not hi:
        return Check(what, MISSING, "no run yet in " + ("either cell" if not lo else "the higher row's cell"))
    at_chance = _at_chance(hi, metric)
    detail = f"no run yet in the lower row's cell; the higher row {_seeds(hi)}"
    if at_chance:
        detail += f", at chance {_chance_note(metric)}"
    return Check(what, MISSING, detail, at_chance, high=hi)


def level(what: str, row: list[Score], ref: list[Score], metric: str, margin: float) -> Check:
    """Whether `row` is within `margin` of `ref` (HOLDS), clearly beyond it (REVERSED) or neither."""
    if not row or not ref:
        return _missing(what, ref, row, metric)
    r, f = _pair(row, ref)
    if not r:
        return Check(what, MISSING, f"no seed in common ({_seeds(row)} against {_seeds(ref)})")
    diffs, diff, se = _paired_gap(r, f)
    at_chance = _at_chance(f, metric)
    beyond = all(abs(d) > margin for d in diffs) and len({d > 0 for d in diffs}) == 1
    if abs(diff) <= margin and not at_chance:
        outcome = HOLDS
    elif beyond and abs(diff) - margin > Z * se:
        outcome = REVERSED
    else:
        outcome = UNCLEAR
    detail = f"{_seeds(r)} against {_seeds(f)}: difference {diff:+.3f} (margin {margin:g}), standard error {se:.3f}"
    if at_chance:
        detail += f"; the reference row at chance {_chance_note(metric)}"
    return Check(what, outcome, detail, at_chance, len(r), ref, f"{_mean(r):.2f} vs {_mean(f):.2f}")


def threshold(what: str, row: list[Score], metric: str, value: float) -> Check:
    """Whether the row's mean is at or above `value` (HOLDS), clearly below it (REVERSED) or neither."""
    if not row:
        return Check(what, MISSING, "no run yet")
    mean, se = _mean(row), _se(row)
    at_chance = _at_chance(row, metric)
    if mean >= value:
        outcome = HOLDS
    elif all(s.value < value for s in row) and value - mean > Z * se:
        outcome = REVERSED
    else:
        outcome = UNCLEAR
    detail = f"{_seeds(row)}: mean {mean:.3f} against {value:g}, standard error {se:.3f}"
    return Check(what, outcome, detail, at_chance, len(row), row, f"{mean:.2f} vs {value:g}")


def faster(what: str, fast: list[Score], slow: list[Score]) -> Check:
    """Whether `fast` crosses its mark more than one evaluation interval before `slow` in every seed both have
    (HOLDS), `slow` first by as much in every seed (REVERSED) or neither; a value is the frames at the crossing, inf
    for a run that never crosses. `chance`: the faster row never crosses in the seeds compared (it has not learned at
    this budget)."""
    if not fast or not slow:
        return Check(
            what,
            MISSING,
            "no run with a metrics.csv here in " + ("either cell" if not fast and not slow else "one cell"),
        )
    f, s = _pair(fast, slow)
    if not f:
        return Check(what, MISSING, f"no seed in common ({_frames(fast)} against {_frames(slow)})")
    # a crossing is known to one evaluation interval: an ordering counts when the crossings are more than one apart
    apart = [max(a.every, b.every) for a, b in zip(f, s)]
    if all(b.value - a.value > gap for a, b, gap in zip(f, s, apart)):
        outcome = HOLDS
    elif all(a.value - b.value > gap for a, b, gap in zip(f, s, apart)):
        outcome = REVERSED
    else:
        outcome = UNCLEAR
    never = all(math.isinf(a.value) for a in f)
    detail = f"{_frames(f)} against {_frames(s)}"
    if never:
        detail += "; the faster row never crosses by its last evaluation"
    numbers = f"{_median_frames(f)} vs {_median_frames(s)}"
    return Check(what, outcome, detail, never, len(f), fast, numbers)


def _frames(scores: list[Score]) -> str:
    return " · ".join(
        f"{frames_text(None if math.isinf(s.value) else int(s.value), s.frames)} (s{s.seed})" for s in scores
    )


def _median_frames(scores: list[Score]) -> str:
    v = float(np.median([s.value for s in scores]))
    return frames_text(None if math.isinf(v) else int(v), max(s.frames for s in scores))


def diagnostic(what: str, row: list[Score], value: float) -> Check:
    """Whether the row's mean diagnostic is at or above `value` (HOLDS), every seed below (REVERSED) or neither;
    `chance`: no run of the row learned its training split (its figure says nothing yet)."""
    if not row:
        return Check(what, MISSING, "no run with a metrics.csv here")
    mean = _mean(row)
    if mean >= value:
        outcome = HOLDS
    elif all(s.value < value for s in row):
        outcome = REVERSED
    else:
        outcome = UNCLEAR
    unlearned = not any(s.learned for s in row)
    detail = (
        " · ".join(f"{s.value:.3f} (s{s.seed}, at {s.frames:,} frames)" for s in row)
        + f": mean {mean:.3f} against {value:g}"
    )
    if unlearned:
        detail += "; the run has not learned its training split (at chance)"
    return Check(what, outcome, detail, unlearned, len(row), row, f"{mean:.2f} vs {value:g}")


def most(what: str, checks: list[Check]) -> Check:
    """'harder': the rows' own comparisons (`order`, one per row) taken together: HOLDS when more than half of the
    rows hold, REVERSED when more than half are reversed, MISSING while a row has no run (the paper's "most models"
    counts every row); `chance` when it does not hold and a row that fails is at chance on the higher metric."""
    absent = [c.what.split(":", 1)[0] for c in checks if c.outcome == MISSING]
    if absent:
        return Check(what, MISSING, f"no run yet for {', '.join(absent)}")
    held = sum(c.outcome == HOLDS for c in checks)
    reversed_ = sum(c.outcome == REVERSED for c in checks)
    if held * 2 > len(checks):
        outcome = HOLDS
    elif reversed_ * 2 > len(checks):
        outcome = REVERSED
    else:
        outcome = UNCLEAR
    detail = "; ".join(f"{c.what}: {c.outcome}, {c.numbers}" + (" (at chance)" if c.chance else "") for c in checks)
    # rows that fail while at chance on the metric the claim puts higher have not learned it at this budget
    chance = outcome != HOLDS and any(c.chance and c.outcome != HOLDS for c in checks)
    seeds = min(c.seeds for c in checks)
    return Check(what, outcome, detail, chance, seeds, [], f"in {held} of {len(checks)} rows")


def _status(checks: list[Check], subject: bool = True) -> str:
    """The claim's status from its comparisons (RULES); `subject`: the row the claim puts higher is one row (not
    'aux_helps'), so that row at chance anywhere leaves the claim unsupported at this budget, cells missing or not."""
    outcomes = [c.outcome for c in checks]
    if any(c.outcome == REVERSED and not c.chance for c in checks):
        return CONTRADICTED
    if any(c.chance and (c.outcome in (REVERSED, UNCLEAR) or (subject and c.outcome == MISSING)) for c in checks):
        return BUDGET
    if MISSING in outcomes:
        return UNTESTABLE
    if all(o == HOLDS for o in outcomes):
        return SUPPORTED
    return BUDGET


def _phrase(status: str, checks: list[Check]) -> str:
    """The evidence in a phrase, per setting: how many comparisons hold, and the one that decides against."""
    groups: dict[str, list[Check]] = {}
    for c in checks:
        groups.setdefault(c.setting, []).append(c)
    parts = []
    for setting, cs in groups.items():
        present = [c for c in cs if c.outcome != MISSING]
        left = len(cs) - len(present)
        chance = [c for c in cs if c.chance and c.outcome != HOLDS]
        if not present:
            if chance:
                values = ", ".join(dict.fromkeys(f"{c.metric} {_mean(c.high):.2f}" for c in chance))
                parts.append(f"{setting}: {chance[0].subject} at chance ({values}), {_n(left)} not run yet")
            else:
                parts.append(f"{setting}: {_n(left)} not run yet")
            continue
        text = f"{setting}: {sum(c.outcome == HOLDS for c in present)} of {len(present)} hold"
        text += f", {left} not run yet" if left else ""
        failing = [c for c in present if c.outcome != HOLDS]
        worst = next((c for c in failing if c.outcome == REVERSED and not c.chance), None) or next(
            (c for c in failing if c.chance), failing[0] if failing else None
        )
        if worst is not None:
            note = f" ({worst.subject} at chance)" if worst.chance else ""
            text += f"; {worst.outcome}: {worst.metric} {worst.what.split(': ', 1)[1]} {worst.numbers}{note}"
        parts.append(text)
    return "; ".join(parts)


def _n(k: int) -> str:
    return f"{k} comparison{'s' if k != 1 else ''}"


def _mean(scores: list[Score]) -> float:
    return float(np.mean([s.value for s in scores]))


def _setting(difficulty: str, aux: bool) -> str:
    from emml.config.env_kinds import env_label

    return f"{env_label(difficulty)} · {'Aux' if aux else 'No Aux'}"


def decide(claim, profile: str, results_root: str | Path | None = None, run_root: str | Path | None = None) -> Decision:
    """The claim decided from the results of `profile` (results/<table>/<profile>.csv and the tables it borrows
    from), by the rules of RULES; 'faster' and 'diagnostic' claims read the runs' metrics.csv under `run_root`
    (default: the profile's)."""
    from emml.experiments.tables import load_table
    from emml.report.tables import build_cells, paper_numbers, table_results

    table = load_table(claim.table)
    results = table_results(table, profile, results_root)
    cells = build_cells(table, profile, results, paper_numbers(table.name))
    rows = {r["run_name"]: r for r in results.to_dict("records")} if not results.empty else {}
    prof = resolve_profile(profile)  # once: every run name below reads it
    runs = table.runs(list(prof.seeds))
    specs = {spec.run_name(prof): spec for spec in runs}
    run_root = run_root if run_root is not None else prof.config().run_root
    curve = claim.kind in ("faster", "diagnostic")
    columns = set(table.metrics.values())

    def cell_metric(m: str) -> str:
        """The table column whose runs a metric reads (a 'faster' claim on sgn_train reads the sgn_test cell's)."""
        return m if m in columns else m.replace("_train", "_test")

    def wanted(c, m: str) -> bool:
        return c.metric == cell_metric(m) and all(
            getattr(c, "difficulty" if k == "difficulty" else "aux") == v for k, v in claim.where.items()
        )

    scores: dict[tuple, list[Score]] = {}
    missing: list[str] = []
    evidence: list[dict] = []
    frames: set[int] = set()
    involved = _involved(claim, table)
    for m in claim.metrics:
        for c in (c for c in cells if wanted(c, m) and c.row in involved):
            per = len(table.cell_columns(c.row, c.metric))
            found, shown = [], {}
            for name, value in zip(c.runs, c.values):
                row = rows[name]
                frames.add(int(row["frames"]))
                if m not in columns and not curve:  # a train column (sgn_train): the same run's results row
                    if _isnan(row.get(m)):
                        missing.append(f"{name} (no {m} in its results row)")
                        continue
                    value = float(row[m])
                score = Score(name, int(row["seed"]), value, int(row["eval_episodes"]) * per, int(row["frames"]))
                if curve:
                    score = _curve_score(claim, m, specs[name], prof, run_root, score, row)
                    if score is None:
                        missing.append(f"{name} (no complete metrics.csv here)")
                        continue
                    shown[score.seed] = (
                        frames_text(None if math.isinf(score.value) else int(score.value), score.frames)
                        if claim.kind == "faster"
                        else f"{score.value:.3f}"
                    )
                else:
                    shown[score.seed] = f"{value:.3f}"
                found.append(score)
            scores[(c.row, c.difficulty, c.aux, m)] = found
            declared = [s.run_name(prof) for s in table.cell_runs(c.row, c.difficulty, c.aux, c.metric, runs)]
            missing += [n for n in declared if n not in c.runs and n not in missing]
            evidence.append(
                {
                    "row": c.row,
                    "setting": _setting(c.difficulty, c.aux),
                    "metric": _metric_label(claim, m),
                    "values": {s.seed: s.value for s in found},
                    "shown": shown,
                    "declared": c.expected,
                }
            )
    checks = _checks(claim, table, scores)
    present = [c.seeds for c in checks if c.outcome != MISSING]
    status = _status(checks, claim.kind != "aux_helps")
    return Decision(
        claim.id,
        claim.text,
        claim.source,
        claim.kind,
        table.name,
        profile,
        status,
        _phrase(status, checks),
        checks,
        evidence,
        missing,
        sorted(frames),
        min(present) if present else 0,
    )


def _metric_label(claim, metric: str) -> str:
    """How the evidence names what it reads: 'SGN test', 'SGN train: frames to leave chance', 'diag/detector_ap'."""
    from emml.experiments.tables import METRIC_LABELS

    if claim.kind == "diagnostic":
        return claim.key
    label = METRIC_LABELS.get(metric, metric)
    return f"{label}: frames until it {MARK_LABELS[claim.mark]}" if claim.kind == "faster" else label


def _curve_score(claim, metric: str, spec, profile: Profile, run_root, score: Score, row: dict) -> Score | None:
    """A run's number for a 'faster' claim (the frames at its first crossing of the mark, inf when it never crosses
    by its last evaluation) or a 'diagnostic' one (the key at its last evaluation), from its metrics.csv; None when
    the file is not here or stops short of the run's frames (a crossing after it cannot be ruled out)."""
    from emml.report.efficiency import run_efficiency
    from emml.runs.rundir import METRICS, path_of
    from emml.runs.tracking import read_mirror

    if claim.kind == "faster":
        eff = run_efficiency(spec, profile, run_root)
        if not eff.found or metric not in eff.crossings:
            return None
        crossed = eff.crossings[metric][claim.mark]
        if crossed is None and eff.last + eff.every < score.frames:
            return None
        value = math.inf if crossed is None else float(crossed)
        return Score(score.run, score.seed, value, 0, eff.last, every=eff.every)
    points = sorted(
        (step, v)
        for step, key, v in read_mirror(path_of(run_root, spec.table, spec.run_name(profile)) / METRICS)
        if key == claim.key
    )
    if not points:
        return None
    learned = any(
        row.get(m) is not None and not _isnan(row.get(m)) and row[m] > _chance(m) + LEAVE
        for m in ("sgn_train", "eqa_train")
    )
    return Score(score.run, score.seed, points[-1][1], 0, points[-1][0], learned=learned)


def _isnan(v) -> bool:
    try:
        return math.isnan(float(v))
    except (TypeError, ValueError):
        return True


def _involved(claim, table) -> set[str]:
    if claim.kind == "best":
        return {r.label for r in table.rows}
    return {*claim.rows, *([claim.than] if claim.than else [])}


def _checks(claim, table, scores: dict[tuple, list[Score]]) -> list[Check]:
    from emml.config.env_kinds import env_label
    from emml.experiments.tables import METRIC_LABELS

    out = []
    keys = sorted({(d, a, m) for (_, d, a, m) in scores}, key=lambda k: (claim.metrics.index(k[2]), k[0], not k[1]))

    def where(d, a, m) -> str:
        return f"{METRIC_LABELS.get(m, m)}, {_setting(d, a)}"

    if claim.kind == "harder":
        hard, easy = claim.metrics
        for d, a in dict.fromkeys((d, a) for (d, a, _) in keys):
            checks = [
                order(
                    f"{row}: {METRIC_LABELS.get(easy, easy)} > {METRIC_LABELS.get(hard, hard)}",
                    scores.get((row, d, a, easy), []),
                    scores.get((row, d, a, hard), []),
                    easy,
                )
                for row in claim.rows
            ]
            what = f"{_setting(d, a)}: below {METRIC_LABELS.get(easy, easy)}"
            out.append(_tag(most(what, checks), _setting(d, a), hard, "most rows"))
        return out
    if claim.kind == "aux_helps":
        for row in claim.rows:
            for d, m in dict.fromkeys((d, m) for (d, _, m) in keys):
                with_, without = scores.get((row, d, True, m), []), scores.get((row, d, False, m), [])
                what = f"{METRIC_LABELS.get(m, m)}, {env_label(d)}: {row} Aux > No Aux"
                out.append(_tag(order(what, with_, without, m), env_label(d), m, f"{row} Aux"))
        return out
    for d, a, m in keys:
        get = lambda row, key=(d, a, m): scores.get((row, *key), [])  # noqa: E731
        if claim.kind == "best":
            top = claim.rows[0]
            for other in (r.label for r in table.rows if r.label != top):
                out.append(
                    _tag(order(f"{where(d, a, m)}: {top} > {other}", get(top), get(other), m), _setting(d, a), m, top)
                )
        elif claim.kind == "below":
            for row in claim.rows:
                check = order(f"{where(d, a, m)}: {claim.than} > {row}", get(claim.than), get(row), m)
                out.append(_tag(check, _setting(d, a), m, claim.than))
        elif claim.kind == "level":
            for row in claim.rows:
                what = f"{where(d, a, m)}: {row} level with {claim.than}"
                out.append(_tag(level(what, get(row), get(claim.than), m, claim.margin), _setting(d, a), m, claim.than))
        elif claim.kind == "faster":
            for row in claim.rows:
                what = f"{where(d, a, m)}: {claim.than} {MARK_LABELS[claim.mark]} before {row}"
                out.append(_tag(faster(what, get(claim.than), get(row)), _setting(d, a), m, claim.than))
        elif claim.kind == "diagnostic":
            for row in claim.rows:
                what = f"{_setting(d, a)}, {claim.key}: {row} ≥ {claim.value:g}"
                out.append(_tag(diagnostic(what, get(row), claim.value), _setting(d, a), claim.key, row))
        elif claim.kind == "at_least":
            for row in claim.rows:
                check = threshold(f"{where(d, a, m)}: {row} ≥ {claim.value:g}", get(row), m, claim.value)
                out.append(_tag(check, _setting(d, a), m, row))
    return out


def _tag(check: Check, setting: str, metric: str, subject: str) -> Check:
    """The check with its setting, metric and higher row named (the phrase groups by setting)."""
    from emml.experiments.tables import METRIC_LABELS

    check.setting, check.metric, check.subject = setting, METRIC_LABELS.get(metric, metric), subject
    return check


def campaign_costs(campaign: str = "reference") -> dict[str, str]:
    """Run name → what it costs to finish, from the campaign's status (its step, state, and the estimates here and
    on a GPU node); {} when the campaign cannot be read. Deterministic for a given tree: it reads run dirs only."""
    try:
        from emml.experiments.campaign import load_campaign, status

        rows = status(load_campaign(campaign))
    except Exception:  # noqa: BLE001 - the costs are optional: a page without them is still the page
        return {}
    out = {}
    for r in rows:
        if r.state == "done":
            continue
        here = f"~{r.seconds_left / 3600:.1f} h here" if r.seconds_left else "no estimate here"
        node = f", ~{r.node_seconds_left / 3600:.1f} h on a GPU node" if r.node_seconds_left else ""
        out[r.run_name] = f"campaign step `{r.step}`, {r.state}: {here}{node}"
    return out


def decide_all(
    profile: str,
    results_root: str | Path | None = None,
    costs: dict[str, str] | None = None,
    run_root: str | Path | None = None,
) -> list:
    """Every claim of reproduce/claims.toml decided from `profile`'s results (and its runs' metrics.csv under
    `run_root`), in the file's order."""
    from emml.experiments.claims import load_claims

    out = []
    for claim in load_claims().values():
        d = decide(claim, profile, results_root, run_root)
        if costs:
            d.costs = [f"`{n}`: {costs[n]}" for n in d.missing if n in costs]
        out.append(d)
    return out


def counts(decisions: list[Decision]) -> dict[str, int]:
    return {s: sum(d.status == s for d in decisions) for s in STATUSES}


def markdown(decisions: list[Decision], profile: str) -> str:
    """The claims page: one line per claim at the top, the rules, then a section per claim."""
    n = counts(decisions)
    frames = sorted({f for d in decisions for f in d.frames})
    lines = [
        f"# Claims ({profile})",
        "",
        f"The paper's claims (reproduce/claims.toml) decided from the '{profile}' profile's results "
        f"({', '.join(f'{f:,}' for f in frames) or 'no'} frames per run), by the rules below. "
        + ", ".join(f"{v} {k}" for k, v in n.items())
        + ". Regenerated by `make reports`.",
        "",
        "| Claim | Status | Evidence |",
        "|:--|:--|:--|",
    ]
    for d in decisions:
        lines.append(f"| [{d.id}](#{d.id}) | {d.label} | {_cell(d.phrase)} |")
    lines += ["", "## Decision rules", ""] + [f"- {r}" for r in RULES]
    if profile != "paper":
        lines += [
            f"- The '{profile}' profile is not the paper's protocol (fewer frames, smaller input: each table page "
            "lists its deviations): 'not supported at this budget' says no more than that.",
        ]
    for d in decisions:
        lines += ["", f'<a id="{d.id}"></a>', "", f"## {d.id}: {d.label}", "", f"> {d.text}", ""]
        lines += [
            f"Paper: {d.source}. Kind `{d.kind}`, decided on [{d.table}-{profile}.md]({d.table}-{profile}.md).",
            "",
        ]
        seeds = sorted({s for e in d.evidence for s in e["values"]})
        if seeds:
            lines += ["| Row | Setting | Metric | " + " | ".join(f"seed {s}" for s in seeds) + " |"]
            lines += ["|:--|:--|:--|" + "--:|" * len(seeds)]
            for e in d.evidence:
                vals = " | ".join(e["shown"].get(s, "—") for s in seeds)
                lines.append(f"| {_cell(e['row'])} | {e['setting']} | {e['metric']} | {vals} |")
            lines.append("")
        elif d.evidence:
            lines += [f"No run of its cells has finished ({len(d.evidence)} cells).", ""]
        lines += ["Comparisons:", ""] + [f"- {_cell(c.what)}: **{c.outcome}** ({_cell(c.detail)})" for c in d.checks]
        if d.missing:
            lines += ["", f"Missing runs ({len(d.missing)}): " + ", ".join(f"`{m}`" for m in d.missing) + "."]
        if d.costs:
            lines += ["", "Their cost (emml campaign reference --status):", ""] + [f"- {c}" for c in d.costs]
    return "\n".join(lines) + "\n"


def _cell(text: str) -> str:
    """Text for a Markdown table cell or line: pipes escaped, '<known_object>' kept as text (not an HTML tag)."""
    return text.replace("|", r"\|").replace("<", "&lt;")


def write_claims(
    profile: str,
    out: str | Path | None = None,
    results_root: str | Path | None = None,
    costs: dict | None = None,
    run_root: str | Path | None = None,
) -> tuple[Path, list[Decision]]:
    """reports/claims-<profile>.md (scratch/reports for a scratch profile, as the table pages: `reports_dir`)."""
    from emml.report.tables import reports_dir

    folder = reports_dir(profile, out)
    folder.mkdir(parents=True, exist_ok=True)
    decisions = decide_all(profile, results_root, costs, run_root)
    path = folder / f"claims-{profile}.md"
    path.write_text(markdown(decisions, profile))
    return path, decisions
