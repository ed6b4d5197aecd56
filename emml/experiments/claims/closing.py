"""Whether a reversed comparison is still closing at this budget (issue 81 item 3b): the gap between the two rows'
greedy evaluation curves (metrics.csv, `eval/<metric>`), fitted against frames over the last third of the
evaluations.

The rule: the gap per evaluation point is the claim's higher row's mean over its seeds minus the lower row's (a
threshold's lower side is its value), turned by the check's `orient` so that it grows towards the claim. Over the
last third of the points (at least MIN_POINTS), an ordinary least-squares slope against frames; the gap is **still
closing** when the slope is positive and its one-sided 95% interval excludes 0: slope − t(0.95, n − 2) × its
standard error > 0 (Student's t, n the points fitted). A flat or falling gap, or one whose slope the interval cannot
tell from 0, is not closing: more frames at this rate would not be expected to overturn it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

LAST = 1 / 3
"""The share of the evaluation points fitted, the last ones (issue 81: 'over the last third of the evaluations')."""
MIN_POINTS = 3
"""The fewest points a slope with an interval is fitted on (n − 2 = 1 degree of freedom)."""
CONFIDENCE = 0.95
"""One-sided: the claim orders the two rows one way, and only a gap growing towards it is asked about."""
PER = 1_000_000
"""The slope's unit: per million frames."""


@dataclass(frozen=True)
class Trend:
    """The gap's slope over the last third of the evaluations."""

    slope: float
    """Per million frames, towards the claim positive."""
    lower: float
    """The one-sided 95% lower bound of the slope (per million frames)."""
    points: int
    """The evaluation points fitted."""
    start: int
    """Frames at the first point fitted."""
    end: int
    """Frames at the last point fitted."""

    @property
    def closing(self) -> bool:
        """Towards the claim, and the interval excludes 0."""
        return self.slope > 0 and self.lower > 0

    def text(self) -> str:
        """'gap slope +0.210 per 1M frames over the last 5 evaluations (0.90M–1.50M), one-sided 95% lower bound
        +0.050: still closing'."""
        verdict = "still closing" if self.closing else "not closing"
        return (
            f"gap slope {self.slope:+.3f} per 1M frames over the last {self.points} evaluations "
            f"({self.start / 1e6:.2f}M–{self.end / 1e6:.2f}M), one-sided {CONFIDENCE:.0%} lower bound "
            f"{self.lower:+.3f}: {verdict}"
        )


def mean_curve(curves: list[dict[int, float]]) -> dict[int, float]:
    """The mean over runs (seeds) at each evaluation point every run has (frames → value)."""
    if not curves:
        return {}
    common = set.intersection(*(set(c) for c in curves))
    return {f: float(np.mean([c[f] for c in curves])) for f in sorted(common)}


def gap_curve(
    high: list[dict[int, float]], low: list[dict[int, float]] | float, orient: float = 1.0
) -> list[tuple[int, float]]:
    """(frames, orient × (high − low)) at each evaluation point both rows' seeds all have; ``low`` a number: a
    threshold's value, the same at every point."""
    hi = mean_curve(high)
    lo = {f: float(low) for f in hi} if isinstance(low, (int, float)) else mean_curve(low)
    return [(f, orient * (hi[f] - lo[f])) for f in sorted(set(hi) & set(lo))]


def last_third(points: list[tuple[int, float]]) -> list[tuple[int, float]]:
    """The last third of the points (rounded up), at least MIN_POINTS; [] when there are fewer than that."""
    if len(points) < MIN_POINTS:
        return []
    return points[-max(MIN_POINTS, math.ceil(len(points) * LAST)) :]


def trend(points: list[tuple[int, float]]) -> Trend | None:
    """The gap's slope over the last third of ``points`` (frames, gap) with its one-sided lower bound; None with
    fewer than MIN_POINTS points (too few to fit a slope with an interval)."""
    fitted = last_third(sorted(points))
    if not fitted:
        return None
    x = np.array([f for f, _ in fitted], dtype=float) / PER
    y = np.array([g for _, g in fitted], dtype=float)
    fit = stats.linregress(x, y)
    se = 0.0 if math.isnan(fit.stderr) else float(fit.stderr)
    t = float(stats.t.ppf(CONFIDENCE, len(fitted) - 2))
    return Trend(float(fit.slope), float(fit.slope) - t * se, len(fitted), fitted[0][0], fitted[-1][0])
