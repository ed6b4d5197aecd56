"""PPO's advantage normalisation (`PPOConfig.norm_adv`, emml/rl/ppo.py `ppo_losses`) on numbers worked out by hand
(issue 66): the advantages of a minibatch, all of its entries together, less their mean, over their standard deviation
(torch's default, the n - 1 one) plus EPS = 1e-8. In float64, so the same on any CPU and torch version: until this file
only tests/rl/test_one_loop.py's recorded parameter digest caught normalisation without the mean, and it is skipped
wherever the CPU or torch differs from the one that recorded it.

The hand batch: advantages A = (1, 2, 3, 6), mean 3, deviations (-2, -1, 0, 3), squares summing to 14, so
s = sqrt(14 / 3) and the normalised advantages are (-2, -1, 0, 3) / s. Ratios r = pi / pi_old = (0.5, 1, 1, 2),
clip 0.2. PPO's loss per entry is max(-A r, -A clip(r, 0.8, 1.2)):
  entry 0: A = -2/s, r = 0.5: max(1/s, 1.6/s) = 1.6/s
  entry 1: A = -1/s, r = 1:   1/s
  entry 2: A = 0:             0
  entry 3: A = 3/s, r = 2:    max(-6/s, -3.6/s) = -3.6/s
mean: (1.6 + 1 - 3.6) / (4 s) = -1 / (4 s) = -sqrt(3/14) / 4, or with EPS beside s, -1 / (4 (s + EPS)).
"""

import math

import pytest
import torch

from emml.rl.ppo import PPOConfig, ppo_losses

RATIOS = (0.5, 1.0, 1.0, 2.0)
S = math.sqrt(14 / 3)  # the n - 1 standard deviation of (1, 2, 3, 6)
EPS = 1e-8  # beside the standard deviation: a batch of equal advantages divides 0 by it, not by 0


def _losses(advantages, ratios=RATIOS, **cfg) -> dict[str, torch.Tensor]:
    """ppo_losses on a minibatch shaped like ``advantages`` whose moves have the given ratios pi / pi_old: uniform
    logits (log pi = -log 4 for every move), pi_old = pi / r, values and returns 0, no supervised answer."""
    adv = torch.tensor(advantages, dtype=torch.float64)
    r = torch.tensor(ratios, dtype=torch.float64).reshape(adv.shape)
    zeros = torch.zeros(adv.shape, dtype=torch.float64)
    return ppo_losses(
        PPOConfig(clip_coef=0.2, **cfg),
        logits=torch.zeros((*adv.shape, 4), dtype=torch.float64),
        values=zeros,
        actions=torch.zeros(adv.shape, dtype=torch.int64),
        old_logprobs=-math.log(4) - r.log(),
        old_values=zeros,
        advantages=adv,
        returns=zeros,
        answer_logits=torch.zeros((*adv.shape, 3), dtype=torch.float64),
        answer_targets=torch.full(adv.shape, -1, dtype=torch.int64),
    )


def test_the_hand_batch_is_normalised_to_zero_mean_and_unit_std():
    out = _losses([1.0, 2.0, 3.0, 6.0])
    assert out["policy"].item() == pytest.approx(-1 / (4 * (S + EPS)), rel=1e-12)
    assert out["policy"].item() == pytest.approx(-math.sqrt(3 / 14) / 4, rel=1e-8)  # EPS aside
    assert out["value"].item() == 0.0 and out["answer"].item() == 0.0
    assert out["clipfrac"].item() == 0.5  # 0.5 and 2 lie outside [0.8, 1.2]


def test_the_mean_is_subtracted():
    """Without the mean (A / s): entries max(-0.5, -0.8)/s, -2/s, -3/s, max(-12, -7.2)/s, a mean of -12.7 / (4 s):
    the loss the normalisation must not give."""
    got = _losses([1.0, 2.0, 3.0, 6.0])["policy"].item()
    assert got != pytest.approx(-12.7 / (4 * S), rel=1e-6)
    # shifting every advantage by a constant leaves the normalised batch, hence the loss, unchanged
    assert _losses([101.0, 102.0, 103.0, 106.0])["policy"].item() == pytest.approx(got, rel=1e-12)
    # 2 A - 9: deviations 2 (-2, -1, 0, 3), std 2 s, so the loss -2 / (4 (2 s + EPS)): the same but for EPS
    assert _losses([-7.0, -5.0, -3.0, 3.0])["policy"].item() == pytest.approx(-2 / (4 * (2 * S + EPS)), rel=1e-12)


def test_the_std_is_the_n_minus_1_one_over_the_whole_minibatch():
    """A (T, B) minibatch is normalised over all of its entries at once, not per step or per actor; the standard
    deviation is torch's default (n - 1): with n it would be sqrt(14 / 4) and the loss -1 / (4 sqrt(3.5))."""
    flat = _losses([1.0, 2.0, 3.0, 6.0])["policy"].item()
    assert _losses([[1.0, 2.0], [3.0, 6.0]])["policy"].item() == pytest.approx(flat, rel=1e-12)
    assert flat != pytest.approx(-1 / (4 * (math.sqrt(3.5) + EPS)), rel=1e-6)


def test_off_or_on_one_entry_the_advantages_are_taken_as_they_are():
    """norm_adv=False: the raw advantages, max(-0.5, -0.8), -2, -3, max(-12, -7.2): a mean of -12.7 / 4. One entry
    has no spread to normalise by (its std is undefined): kept as it is, -A at r = 1."""
    assert _losses([1.0, 2.0, 3.0, 6.0], norm_adv=False)["policy"].item() == pytest.approx(-12.7 / 4, rel=1e-12)
    assert _losses([5.0], ratios=(1.0,))["policy"].item() == pytest.approx(-5.0, rel=1e-12)


def test_equal_advantages_normalise_to_zero_not_nan():
    """Every advantage the same (a batch where every episode ends alike): the spread is 0, the 1e-8 keeps the
    division finite, and every normalised advantage is 0: no policy gradient, not NaN."""
    out = _losses([2.0, 2.0, 2.0, 2.0])
    assert out["policy"].item() == 0.0 and math.isfinite(out["total"].item())
