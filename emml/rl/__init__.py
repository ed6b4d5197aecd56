"""Reinforcement-learning core: rollout storage with GAE, PPO losses (checkpoints: emml/runs/checkpoint.py).

The paper trains the navigation policy with PPO (Schulman et al. 2017) and the
answer head with a supervised cross-entropy loss, plus an optional spatial
auxiliary loss (binary cross-entropy on the conv3 feature maps).
"""

from emml.rl.ppo import (
    PPOConfig,
    answer_loss,
    aux_loss,
    entropy,
    explained_variance,
    make_optimizer,
    move_logprob,
    policy_loss,
    ppo_losses,
    ppo_update,
    value_loss,
)
from emml.rl.rollout import RolloutBuffer, compute_gae

__all__ = [
    "PPOConfig",
    "RolloutBuffer",
    "answer_loss",
    "aux_loss",
    "compute_gae",
    "entropy",
    "explained_variance",
    "make_optimizer",
    "move_logprob",
    "policy_loss",
    "ppo_losses",
    "ppo_update",
    "value_loss",
]
