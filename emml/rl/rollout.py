"""On-policy rollout storage and Generalized Advantage Estimation.

One PPO update consumes one rollout of ``num_steps`` (the paper's horizon, 128)
steps from ``num_envs`` parallel actors (the paper's 8). Storage is allocated
once and overwritten every rollout. Images stay ``uint8`` end to end: the
buffer never holds float copies of frames (a 128 x 8 x 3 x 168 x 300 rollout is
~155 MB as uint8 and would be ~620 MB as float32).

Episode-boundary conventions (all arrays are indexed ``[t, env]``):

* ``dones[t]`` is True when the transition taken at step ``t`` ended the
  episode (terminated *or* hit the 210-step time limit). The value of the next
  observation is then not bootstrapped.
* ``episode_starts[t]`` is True when the observation at step ``t`` is the first
  of an episode; the recurrent state must be reset before processing it. Within
  a rollout ``episode_starts[t + 1] == dones[t]``; ``episode_starts[0]`` carries
  the information across rollout boundaries.

Why truncation is treated as a true terminal: the observation includes the
episode time step (``obs["time"]``, used by the paper's time embedding), so the
state at the time limit is Markov-terminal -- the value of a state with
``time == max_steps`` is exactly zero under the environment's dynamics. No
special "bootstrap on truncation" correction (as needed for time-unaware
agents, Pardo et al. 2018) is required.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

Shape = tuple[int, ...]


def compute_gae(
    rewards: torch.Tensor,
    values: torch.Tensor,
    dones: torch.Tensor,
    last_value: torch.Tensor,
    gamma: float,
    lam: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Generalized Advantage Estimation (Schulman et al. 2016, Eq. 11-12).

    Args:
        rewards: (T, ...) reward received after the action at step t.
        values: (T, ...) V(s_t) from the behaviour policy's critic.
        dones: (T, ...) bool, the transition at step t ended the episode.
        last_value: (...) V(s_T), the value of the observation after the rollout.
        gamma: discount factor.
        lam: GAE lambda (1 = Monte-Carlo advantages, 0 = one-step TD error).

    Returns:
        (advantages, returns), both (T, ...) float32, with
        returns = advantages + values (the TD(lambda) return used as value target).
    """
    if rewards.shape != values.shape or rewards.shape != dones.shape:
        raise ValueError(
            f"rewards {tuple(rewards.shape)}, values {tuple(values.shape)} and dones "
            f"{tuple(dones.shape)} must have the same (T, ...) shape"
        )
    if last_value.shape != values.shape[1:]:
        raise ValueError(f"last_value shape {tuple(last_value.shape)} != {tuple(values.shape[1:])}")
    rewards = rewards.float()
    values = values.float()
    not_done = 1.0 - dones.float()
    advantages = torch.zeros_like(values)
    next_value = last_value.float()
    next_adv = torch.zeros_like(next_value)
    for t in reversed(range(rewards.shape[0])):
        # Eq. 12 (TD residual): delta_t = r_t + gamma * V(s_{t+1}) - V(s_t); no bootstrap across a done.
        delta = rewards[t] + gamma * next_value * not_done[t] - values[t]
        # Eq. 11 (recursive form): A_t = delta_t + gamma * lambda * A_{t+1}, cut at episode ends.
        next_adv = delta + gamma * lam * not_done[t] * next_adv
        advantages[t] = next_adv
        next_value = values[t]
    return advantages, advantages + values


def _as_dtype(dtype: torch.dtype | str) -> torch.dtype:
    if isinstance(dtype, torch.dtype):
        return dtype
    resolved = getattr(torch, str(dtype), None)
    if not isinstance(resolved, torch.dtype):
        raise TypeError(f"unknown dtype {dtype!r}")
    return resolved


def _storage(tb: Shape, shape: Shape, dtype: torch.dtype, device, channels_last: bool) -> torch.Tensor:
    """Zeros of shape (T, B, *shape); with ``channels_last`` a (C, H, W) frame is laid out (H, W, C) in memory,
    the layout the conv stack runs in (emml/models/encoders.py): a (T·B, C, H, W) batch of it is channels_last as
    stored, and the update converts nothing. Storing a step copies into it either way."""
    if channels_last and len(shape) == 3:
        c, h, w = shape
        return torch.zeros(tb + (h, w, c), dtype=dtype, device=device).permute(0, 1, 4, 2, 3)
    return torch.zeros(tb + shape, dtype=dtype, device=device)


class RolloutBuffer:
    """Preallocated (T, B) storage for one on-policy rollout.

    Args:
        num_steps: T, the rollout horizon (paper: 128).
        num_envs: B, the number of parallel actors (paper: 8).
        obs_shapes: ``{key: (per_env_shape, dtype)}`` for every observation key,
            shapes *without* the leading (T, B); e.g.
            ``{"image": ((3, 168, 300), torch.uint8), "tokens": ((L,), torch.int64),
            "task": ((), torch.int64), "time": ((), torch.int64)}`` and optionally
            ``"aux": ((V, h, w), torch.uint8)``.
        device: where the storage lives.

    Attributes (all (T, B, ...)): ``obs[key]``, ``actions`` int64 (move 0..3),
    ``answer_targets`` int64 (-1 = no answer supervision), ``logprobs``,
    ``values``, ``rewards`` float32, ``dones``, ``episode_starts`` bool,
    and after :meth:`compute_returns` ``advantages`` / ``returns`` float32.
    ``initial_state`` is the recurrent state (dict of (B, ...) tensors) at t = 0.
    """

    def __init__(
        self,
        num_steps: int,
        num_envs: int,
        obs_shapes: Mapping[str, tuple[Shape, torch.dtype | str]],
        device: torch.device | str = "cpu",
    ) -> None:
        if num_steps <= 0 or num_envs <= 0:
            raise ValueError(f"num_steps and num_envs must be positive, got {num_steps}, {num_envs}")
        self.num_steps = num_steps
        self.num_envs = num_envs
        self.device = torch.device(device)
        tb = (num_steps, num_envs)
        self.obs: dict[str, torch.Tensor] = {
            key: _storage(tb, tuple(shape), _as_dtype(dtype), self.device, channels_last=key == "image")
            for key, (shape, dtype) in obs_shapes.items()
        }
        self.actions = torch.zeros(tb, dtype=torch.int64, device=self.device)
        self.answer_targets = torch.full(tb, -1, dtype=torch.int64, device=self.device)
        self.logprobs = torch.zeros(tb, dtype=torch.float32, device=self.device)
        self.values = torch.zeros(tb, dtype=torch.float32, device=self.device)
        self.rewards = torch.zeros(tb, dtype=torch.float32, device=self.device)
        self.dones = torch.zeros(tb, dtype=torch.bool, device=self.device)
        self.episode_starts = torch.zeros(tb, dtype=torch.bool, device=self.device)
        self.advantages = torch.zeros(tb, dtype=torch.float32, device=self.device)
        self.returns = torch.zeros(tb, dtype=torch.float32, device=self.device)
        self.initial_state: dict[str, torch.Tensor] = {}

    def _put(self, name: str, dest: torch.Tensor, value, t: int, envs: slice = slice(None)) -> None:
        src = torch.as_tensor(value).detach()  # never let autograd history into storage
        if src.is_floating_point() and not dest.is_floating_point():
            # Refuse silent truncation (e.g. a normalised float image into uint8 storage).
            raise TypeError(f"{name}: cannot store floating {src.dtype} into {dest.dtype} storage")
        target = dest[t, envs]
        if src.shape != target.shape:
            raise ValueError(f"{name}: expected shape {tuple(target.shape)}, got {tuple(src.shape)}")
        target.copy_(src, non_blocking=True)

    def insert(
        self,
        t: int,
        obs: Mapping[str, torch.Tensor],
        action,
        answer_target,
        logprob,
        value,
        reward,
        done,
        episode_start,
        envs: slice = slice(None),
    ) -> None:
        """Store step ``t`` for the envs ``envs`` (all B by default; every argument has their leading dim).

        ``obs`` must hold exactly the keys given at construction.
        """
        self.insert_policy(t, obs, action, answer_target, logprob, value, episode_start, envs)
        self.insert_outcome(t, reward, done, envs)

    def insert_policy(
        self, t: int, obs, action, answer_target, logprob, value, episode_start, envs: slice = slice(None)
    ) -> None:
        """The half of step ``t`` known when the policy acts: observation, action, log-prob, value, episode start.
        (Double-buffered sampling stores it before the env has stepped; `insert_outcome` follows.)"""
        if not 0 <= t < self.num_steps:
            raise IndexError(f"t={t} outside [0, {self.num_steps})")
        if set(obs) != set(self.obs):
            raise KeyError(f"obs keys {sorted(obs)} != buffer keys {sorted(self.obs)}")
        for key, tensor in obs.items():
            self._put(f"obs[{key!r}]", self.obs[key], tensor, t, envs)
        self._put("action", self.actions, action, t, envs)
        self._put("answer_target", self.answer_targets, answer_target, t, envs)
        self._put("logprob", self.logprobs, logprob, t, envs)
        self._put("value", self.values, value, t, envs)
        self._put("episode_start", self.episode_starts, episode_start, t, envs)

    def insert_outcome(self, t: int, reward, done, envs: slice = slice(None)) -> None:
        """The half of step ``t`` the env returns: reward and done."""
        if not 0 <= t < self.num_steps:
            raise IndexError(f"t={t} outside [0, {self.num_steps})")
        self._put("reward", self.rewards, reward, t, envs)
        self._put("done", self.dones, done, t, envs)

    def set_initial_state(self, state: Mapping[str, torch.Tensor]) -> None:
        """Record the recurrent state at t = 0 (detached clones, on the buffer's device)."""
        for key, tensor in state.items():
            if tensor.shape[0] != self.num_envs:
                raise ValueError(f"state[{key!r}] leading dim {tensor.shape[0]} != num_envs {self.num_envs}")
        self.initial_state = {k: v.detach().to(self.device).clone() for k, v in state.items()}

    def compute_returns(self, last_value: torch.Tensor, gamma: float, gae_lambda: float) -> None:
        """Fill ``advantages`` and ``returns`` with GAE (Eq. 11-12); ``last_value`` is (B,) V(s_T)."""
        last_value = torch.as_tensor(last_value, dtype=torch.float32, device=self.device).detach()
        adv, ret = compute_gae(self.rewards, self.values, self.dones, last_value, gamma, gae_lambda)
        self.advantages.copy_(adv)
        self.returns.copy_(ret)
