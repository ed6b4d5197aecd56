"""Whether a reversed comparison is settled: what a second seed and more frames would not overturn (issue 81 item 3).

A REVERSED check (a row that learned, and loses by the rule) counts towards 'contradicted' only when both hold:

(a) **seeds**: each row it compares has two seeds or more; or, for a row on one seed, the comparison is still
    reversed once that row's error includes a between-seed variance borrowed from the nearest cell of the same row
    (model) with two seeds or more (same table; the same difficulty first, then the same aux: emml/report/
    claims_settle.py finds it and names it). A rule with no error term ('faster', 'diagnostic') has nothing to
    borrow into: it needs the seeds themselves. Otherwise: ONE_SEED, settled by the missing seed's run.
(b) **flat**: the gap is not still closing over the last third of the evaluations (emml/experiments/claims/
    closing.py: slope towards the claim whose one-sided 95% interval excludes 0). Closing: CLOSING, settled by more
    frames. A run with no curve of the metric here (no metrics.csv; a transfer score, which is no curve): flatness
    unknown, UNKNOWN_FLAT. A 'faster' reversal is of crossings already made: more frames cannot undo it.

'most' ('harder') is settled when more than half of its rows are settled reversals. The paper's own tables are not
weighed here: their numbers are what the paper printed, one each.
"""

from __future__ import annotations

from collections.abc import Callable

from emml.experiments.claims.closing import gap_curve, trend
from emml.experiments.claims.evidence import (
    CLOSING,
    ONE_SEED,
    PROVISIONAL,
    REVERSED,
    UNKNOWN_FLAT,
    Check,
    Score,
    Z,
    gap_error,
)

Curve = Callable[[Score], "dict[int, float] | None"]
"""A run's evaluation curve of the score's metric (frames → rate), None when it is not here."""
Second = Callable[[list[Score]], str]
"""The run that would give a one-seed row its next seed ('table2/text_only-easy-aux-s1-quick')."""
MORE_FRAMES = "more frames"


def settle(check: Check, curve: Curve, second: Second) -> Check:
    """Weigh a REVERSED, learned check for being settled: sets `unsettled` (one of PROVISIONAL, '' when settled),
    `settlement` (why) and `settle_by` (what would settle it). Any other check is returned as it is."""
    if check.outcome != REVERSED or check.chance:
        return check
    if check.parts:
        return _settle_most(check, curve, second)
    sides = [r for r in (check.high, check.low) if r]
    seeds_ok, seeds_note, by = _seeds(check, sides, second)
    flat, flat_note = _flat(check, curve)
    check.unsettled = ONE_SEED if not seeds_ok else CLOSING if flat is False else UNKNOWN_FLAT if flat is None else ""
    if flat is False:
        by.append(MORE_FRAMES)
    check.settlement = "; ".join(x for x in (seeds_note, flat_note) if x)
    check.settle_by = by
    return check


def _seeds(check: Check, sides: list[list[Score]], second: Second) -> tuple[bool, str, list[str]]:
    """(a): settled on seeds, why, and the runs that would settle it."""
    few = [r for r in sides if len(r) < 2]
    counts = " and ".join(str(len(r)) for r in sides)
    if not few:
        return True, f"seeds {counts}", []
    runs = [second(r) for r in few]
    if check.against is None:
        return False, f"seeds {counts}: a rule without an error term, a second seed decides", runs
    lacking = [r[0].run for r in few if r[0].borrowed <= 0]
    if lacking:
        note = f"seeds {counts}: no cell of the same row with 2 seeds to borrow a spread from for {', '.join(lacking)}"
        return False, note, runs
    se = gap_error(check.high, check.low, borrow=True)
    held = check.against > Z * se
    sources = "; ".join(f"{r[0].borrowed_from} (variance {r[0].borrowed:.4f})" for r in few)
    verdict = "still reversed" if held else "within it"
    note = (
        f"seeds {counts}: between-seed variance borrowed from {sources}: standard error {se:.3f}, "
        f"{check.against:+.3f} beyond the boundary against {Z:g} × {se:.3f}: {verdict}"
    )
    return held, note, [] if held else runs


def _flat(check: Check, curve: Curve) -> tuple[bool | None, str]:
    """(b): True flat (not closing), False still closing, None unknown; and the slope with its interval."""
    if not check.high or not check.high[0].metric:
        return True, "a crossing already made: more frames cannot undo it"
    high = [_curve(s, curve) for s in check.high]
    low = [_curve(s, curve) for s in check.low] if check.low else check.floor
    absent = [s.run for s, c in zip([*check.high, *check.low], [*high, *(low if check.low else [])]) if c is None]
    if absent or low is None:
        return None, f"flatness unknown: no {check.high[0].metric} curve here for {', '.join(absent) or 'its runs'}"
    found = trend(gap_curve(high, low, check.orient))
    if found is None:
        return None, "flatness unknown: too few evaluations to fit a slope"
    return (not found.closing), found.text()


def _curve(score: Score, curve: Curve) -> dict[int, float] | None:
    """The run's curve up to the frames its score was read at, as the score reads it (above its chance where it
    is: `Score.chance`)."""
    points = curve(score)
    if points is None:
        return None
    c = score.chance
    return {f: (v if c is None else (v - c) / (1 - c)) for f, v in points.items() if f <= score.frames}


def _settle_most(check: Check, curve: Curve, second: Second) -> Check:
    """'most': settled when more than half of its rows are settled reversals (a row that has not learned counts as
    `most` counts it: reversed as it stands); else the first provisional status among its reversed rows."""
    parts = [settle(p, curve, second) for p in check.parts]
    reversed_ = [p for p in parts if p.outcome == REVERSED]
    settled = [p for p in reversed_ if not p.unsettled]
    if len(settled) * 2 > len(parts):
        check.unsettled = ""
    else:
        check.unsettled = next((s for s in PROVISIONAL if any(p.unsettled == s for p in reversed_)), ONE_SEED)
    check.settlement = f"{len(settled)} of {len(parts)} rows settled reversals: " + "; ".join(
        f"{p.where}: {p.unsettled or 'settled'} ({p.settlement})" for p in reversed_
    )
    check.settle_by = list(dict.fromkeys(r for p in reversed_ if p.unsettled for r in p.settle_by))
    return check
