"""GAE (Schulman et al. 2016 Eq. 11-12) against independent hand computations."""

import numpy as np
import pytest
import torch

from emml.rl.rollout import compute_gae


def _sb3_oracle(rollout_size, max_steps, value, gamma, lam):
    """Stable-Baselines3's test_gae oracle: reward 1 only on each episode's last step, constant V."""
    rewards = np.zeros(rollout_size)
    rewards[max_steps - 1 :: max_steps] = 1.0
    episode_starts = np.zeros(rollout_size)
    episode_starts[::max_steps] = 1.0
    adv = np.zeros(rollout_size)
    last = rewards[-1] - value  # rollout ends on a terminal step
    adv[-1] = last
    for n in reversed(range(rollout_size - 1)):
        mask = 1.0 - episode_starts[n + 1]
        delta = rewards[n] + gamma * value * mask - value
        last = delta + gamma * lam * last * mask
        adv[n] = last
    return rewards, adv


@pytest.mark.parametrize("gamma,lam", [(0.99, 0.95), (0.9, 1.0), (0.5, 0.0), (1.0, 1.0), (0.99, 0.5)])
@pytest.mark.parametrize("value", [0.0, 1.0, -0.3])
def test_matches_sb3_oracle(gamma, lam, value):
    size, max_steps, num_envs = 32, 8, 3
    rewards_np, adv_np = _sb3_oracle(size, max_steps, value, gamma, lam)
    rewards = torch.tensor(rewards_np, dtype=torch.float32)[:, None].repeat(1, num_envs)
    values = torch.full((size, num_envs), value)
    dones = torch.zeros(size, num_envs, dtype=torch.bool)
    dones[max_steps - 1 :: max_steps] = True
    last_value = torch.full((num_envs,), 123.0)  # must be ignored: last step is terminal
    adv, ret = compute_gae(rewards, values, dones, last_value, gamma, lam)
    expected = torch.tensor(adv_np, dtype=torch.float32)[:, None].expand(-1, num_envs)
    torch.testing.assert_close(adv, expected, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(ret, expected + value)


def test_closed_forms():
    # lambda = 1: A_t = discounted return to episode end - V(s_t) (telescoping sum).
    gamma, max_steps = 0.9, 5
    rewards = torch.zeros(10, 1)
    rewards[max_steps - 1 :: max_steps] = 1.0
    dones = rewards.bool()
    values = torch.full((10, 1), 0.25)
    adv, _ = compute_gae(rewards, values, dones, torch.zeros(1), gamma, 1.0)
    k = torch.tensor([4, 3, 2, 1, 0] * 2, dtype=torch.float32)[:, None]
    torch.testing.assert_close(adv, gamma**k - 0.25)
    # lambda = 0: A_t = one-step TD error.
    adv0, _ = compute_gae(rewards, values, dones, torch.zeros(1), gamma, 0.0)
    td = rewards + gamma * 0.25 * (~dones).float() - values
    torch.testing.assert_close(adv0, td)


def test_done_in_middle_cuts_bootstrap_and_last_value_used():
    gamma, lam = 0.5, 0.5
    rewards = torch.tensor([[1.0], [2.0], [4.0]])
    values = torch.tensor([[10.0], [20.0], [30.0]])
    dones = torch.tensor([[False], [True], [False]])
    last_value = torch.tensor([8.0])
    adv, ret = compute_gae(rewards, values, dones, last_value, gamma, lam)
    # by hand (backwards):
    d2 = 4 + 0.5 * 8 - 30  # -22, bootstraps from last_value
    a2 = d2
    d1 = 2 + 0 - 20  # -18, episode ended: no V(s_2), no A_2
    a1 = d1
    d0 = 1 + 0.5 * 20 - 10  # 1
    a0 = d0 + 0.25 * a1  # 1 - 4.5 = -3.5
    torch.testing.assert_close(adv, torch.tensor([[a0], [a1], [a2]]))
    torch.testing.assert_close(ret, adv + values)
    # Changing anything after the done leaves the earlier episode untouched.
    adv_b, _ = compute_gae(rewards * torch.tensor([[1.0], [1.0], [99.0]]), values, dones, last_value * 7, gamma, lam)
    torch.testing.assert_close(adv_b[:2], adv[:2])


def test_shape_errors():
    with pytest.raises(ValueError):
        compute_gae(torch.zeros(3, 2), torch.zeros(3, 2), torch.zeros(3, 1, dtype=torch.bool), torch.zeros(2), 0.9, 0.9)
    with pytest.raises(ValueError):
        compute_gae(torch.zeros(3, 2), torch.zeros(3, 2), torch.zeros(3, 2, dtype=torch.bool), torch.zeros(3), 0.9, 0.9)
