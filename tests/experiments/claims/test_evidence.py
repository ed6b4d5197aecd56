"""The rules that weigh a claim's evidence (emml/experiments/claims/evidence.py, issue 60), on numbers worked out by
hand: the error of a row with several seeds includes their spread, 'learned' reads every seed's training split,
chance is the blind row's score never below the uniform one."""

import math

import pytest

from emml.experiments.claims.evidence import (
    HOLDS,
    REVERSED,
    UNCLEAR,
    Chance,
    Score,
    Z,
    gap_error,
    learned,
    order,
    variance_of_mean,
)


def s(value, seed=0, train=0.9, bar=0.3, episodes=500):
    return Score("r", seed, value, episodes, 1_500_000, train, bar)


def test_the_test_is_one_sided_at_95_percent():
    assert Z == pytest.approx(1.645)


def test_one_seed_has_the_binomial_error_alone():
    # 0.5 on 500 episodes: 0.25 / 500 = 0.0005
    assert variance_of_mean([s(0.5)]) == pytest.approx(0.0005)


def test_several_seeds_have_their_spread_when_it_exceeds_the_binomial_error():
    # 0.5 and 0.7: mean 0.6, sample variance (0.01 + 0.01) / 1 = 0.02 > binomial (0.25 + 0.21) / 2 / 500; / 2 seeds
    assert variance_of_mean([s(0.5), s(0.7, 1)]) == pytest.approx(0.01)
    # two equal seeds: no spread, the binomial floor stays: 0.25 / 500 / 2
    assert variance_of_mean([s(0.5), s(0.5, 1)]) == pytest.approx(0.00025)


def test_the_spread_between_seeds_can_make_a_gap_unclear():
    """0.5 / 0.7 against 0.45 on one seed: gap 0.15; binomial alone (se 0.031) it holds, with the spread (se
    sqrt(0.01 + 0.000495) = 0.1024, times 1.645 = 0.168) it does not."""
    hi, lo = [s(0.5), s(0.7, 1)], [s(0.45)]
    assert gap_error(hi, lo) == pytest.approx(math.sqrt(0.01 + 0.45 * 0.55 / 500))
    assert order("x", hi, lo).outcome == UNCLEAR
    assert order("x", [s(0.5), s(0.5, 1)], [s(0.3)]).outcome == HOLDS


def test_a_gap_just_inside_z_standard_errors_is_no_win_and_just_outside_is():
    """0.52 against 0.48 on 500 episodes each: se sqrt(2 × 0.2496 / 500) = 0.0316, 1.645 se = 0.052: a gap of 0.04
    is inside (at Z = 1 it would count), 0.06 outside."""
    assert order("x", [s(0.52)], [s(0.48)]).outcome == UNCLEAR
    assert order("x", [s(0.53)], [s(0.47)]).outcome == HOLDS
    assert order("x", [s(0.47)], [s(0.53)]).outcome == REVERSED


def test_learned_reads_every_seed_of_the_row():
    """Seed 0 below its bar, seeds 1 and 2 far above: the row's mean training score (0.25 + 0.9 + 0.9) / 3 = 0.68
    is above 0.3, so the row learned; read on seed 0 alone it would not have."""
    row = [s(0.3, 0, train=0.25), s(0.3, 1), s(0.3, 2)]
    assert learned(row) and not learned(row[:1])
    check = order("x", row, [s(0.5)])
    assert check.outcome == REVERSED and not check.chance  # it learned, and loses
    assert order("x", row[:1], [s(0.5)]).chance  # unlearned: excused


def test_a_row_without_a_training_score_is_read_on_its_cell():
    assert learned([Score("paper", 0, 0.58, 500, 0, None, 0.43)])
    assert not learned([Score("paper", 0, 0.40, 500, 0, None, 0.43)])


def test_the_blind_row_is_never_excused():
    blind = [Score("text_only", 0, 0.45, 500, 0, 0.38, -math.inf)]  # its train score is the chance line itself
    assert learned(blind)


def test_chance_is_the_blind_row_never_below_uniform():
    chance = Chance({("easy", "eqa_test"): 0.45, ("easy", "sgn_test"): 0.194}, "fixture")
    assert chance.of("eqa_test", "easy") == pytest.approx(0.45)
    assert chance.of("sgn_test", "easy") == pytest.approx(0.2)  # 0.194 measured: the uniform 0.2 is the floor
    assert chance.of("sgn_transfer", "easy") == pytest.approx(0.2)  # a transfer instruction: SGN, test split
    assert chance.of("eqa_test", "hard") == pytest.approx(1 / 3) and not chance.measured("eqa_test", "hard")
    assert chance.bar("eqa_test", "easy") == pytest.approx(0.55)
