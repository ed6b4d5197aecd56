"""Whether a reversed comparison is still closing (emml/experiments/claims/closing.py, issue 81 item 3b), on gaps
worked out by hand: the last third of the evaluations, an ordinary least-squares slope per million frames, and its
one-sided 95% lower bound (Student's t with n − 2 degrees of freedom)."""

import pytest

from emml.experiments.claims.closing import gap_curve, last_third, mean_curve, trend


def at(*gaps: float, start: int = 100_000, step: int = 100_000) -> list[tuple[int, float]]:
    return [(start + i * step, g) for i, g in enumerate(gaps)]


def test_the_last_third_rounded_up_and_never_fewer_than_three_points():
    assert [f for f, _ in last_third(at(*range(15)))] == [1_100_000, 1_200_000, 1_300_000, 1_400_000, 1_500_000]
    assert len(last_third(at(*range(10)))) == 4  # ceil(10 / 3)
    assert len(last_third(at(*range(4)))) == 3
    assert last_third(at(0, 1)) == [] and trend(at(0, 1)) is None


def test_a_gap_rising_towards_the_claim_beyond_its_interval_is_closing():
    """Six points; the last third: −0.30, −0.18, −0.10 at 0.5M, 0.6M, 0.7M. Slope: Sxy / Sxx = 0.02 / 0.02 = 1.0
    per 1M frames; residuals −0.00667, +0.01333, −0.00667, SSE 0.000267, se sqrt(0.000267 / 1 / 0.02) = 0.1155;
    t(0.95, 1) = 6.314: lower bound 1.0 − 0.729 = +0.271 > 0. A two-sided bound (t(0.975, 1) = 12.71) would not
    exclude 0 (1.0 − 1.467 < 0)."""
    found = trend(at(-0.9, -0.8, -0.7, -0.30, -0.18, -0.10))
    assert found.points == 3 and (found.start, found.end) == (400_000, 600_000)
    assert found.slope == pytest.approx(1.0)
    assert found.lower == pytest.approx(1.0 - 6.3138 * 0.11547, abs=1e-3)
    assert found.closing
    assert "gap slope +1.000 per 1M frames over the last 3 evaluations" in found.text()
    assert found.text().endswith("still closing")


def test_a_rising_gap_whose_interval_holds_zero_and_a_falling_one_are_not_closing():
    """−0.30, −0.10, −0.20: slope 0.5, residuals −0.05, +0.1, −0.05, SSE 0.015, se sqrt(0.015 / 0.02) = 0.866:
    lower bound 0.5 − 5.47 < 0 (towards the claim, but not told from 0). Falling: slope −1.0. Flat: 0, se 0."""
    noisy = trend(at(-0.30, -0.10, -0.20))
    assert noisy.slope == pytest.approx(0.5) and noisy.lower < 0 and not noisy.closing
    falling = trend(at(-0.10, -0.20, -0.30))
    assert falling.slope == pytest.approx(-1.0) and falling.lower == pytest.approx(-1.0) and not falling.closing
    flat = trend(at(-0.2, -0.2, -0.2))
    assert flat.slope == pytest.approx(0.0) and not flat.closing
    assert falling.text().endswith("not closing")


def test_the_gap_is_of_the_means_over_seeds_at_the_points_every_run_has():
    """High: two seeds (0.4, 0.6 at 100; 0.5, 0.7 at 200; one has 300 too); low: 0.3 and 0.4. Means 0.5 and 0.6
    at the points both seeds have; gap 0.2 at each; turned by orient −1 for a level row below its reference."""
    high = [{100: 0.4, 200: 0.5, 300: 0.9}, {100: 0.6, 200: 0.7}]
    assert mean_curve(high) == {100: pytest.approx(0.5), 200: pytest.approx(0.6)}
    low = [{100: 0.3, 200: 0.4}]
    assert gap_curve(high, low) == [(100, pytest.approx(0.2)), (200, pytest.approx(0.2))]
    assert gap_curve(high, low, -1.0) == [(100, pytest.approx(-0.2)), (200, pytest.approx(-0.2))]
    assert gap_curve(high, 0.8) == [(100, pytest.approx(-0.3)), (200, pytest.approx(-0.2))]  # a threshold's value
    assert mean_curve([]) == {}
