"""PPO objective (Schulman et al. 2017) plus the paper's supervised heads.

The paper ("Optimization" paragraph) trains the whole model jointly: the
4-way move policy with PPO, the answer distribution with a supervised
cross-entropy loss, and -- when enabled -- the spatial auxiliary task (one
conv3 channel per vocabulary word) with a per-pixel binary cross-entropy.
PPO's ratio, clipping and entropy bonus act on the move distribution only.

Every loss term is a pure function of tensors so it can be unit-tested in
isolation; :func:`ppo_losses` combines them and :func:`ppo_update` runs the
epochs/minibatches/optimiser loop over a :class:`~emml.rl.rollout.RolloutBuffer`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping

import torch
import torch.nn.functional as F

from emml.config.schema import (
    AUX_BALANCES,
    PPOConfig,  # defined beside TrainConfig (configs are leaves); still importable from here
    check_choice,
)
from emml.rl.rollout import RolloutBuffer

# ---------------------------------------------------------------------------
# Pure loss terms. All accept any leading shape ((T, B) or flattened (N,)).
# ---------------------------------------------------------------------------


def move_logprob(logits: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """log pi(a | s) of the chosen move under ``logits`` (..., 4)."""
    return torch.log_softmax(logits, dim=-1).gather(-1, actions.long().unsqueeze(-1)).squeeze(-1)


def entropy(logits: torch.Tensor) -> torch.Tensor:
    """Per-entry entropy of the categorical move distribution; shape ``logits.shape[:-1]``."""
    logp = torch.log_softmax(logits, dim=-1)
    return -(logp.exp() * logp).sum(-1)


def policy_loss(
    new_logprob: torch.Tensor,
    old_logprob: torch.Tensor,
    advantages: torch.Tensor,
    clip_coef: float,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Clipped surrogate objective (PPO Eq. 7), negated for minimisation.

    L = -E[min(r_t A_t, clip(r_t, 1 - eps, 1 + eps) A_t)], r_t = pi/pi_old.

    Returns (loss, approx_kl, clipfrac); the last two are detached diagnostics:
    approx_kl = E[(r - 1) - log r] (unbiased, non-negative KL(old||new) estimator)
    and clipfrac = fraction of entries with |r - 1| > eps.
    """
    log_ratio = new_logprob - old_logprob.detach()
    ratio = log_ratio.exp()
    advantages = advantages.detach()
    unclipped = -advantages * ratio
    clipped = -advantages * torch.clamp(ratio, 1.0 - clip_coef, 1.0 + clip_coef)
    loss = torch.max(unclipped, clipped).mean()  # PPO Eq. 7 (max of negatives = min of objectives)
    with torch.no_grad():
        approx_kl = ((ratio - 1.0) - log_ratio).mean()
        clipfrac = ((ratio - 1.0).abs() > clip_coef).float().mean()
    return loss, approx_kl, clipfrac


def value_loss(
    new_value: torch.Tensor,
    returns: torch.Tensor,
    old_value: torch.Tensor,
    clip_coef: float,
    clip: bool,
) -> torch.Tensor:
    """0.5 * squared error to the GAE returns; optionally PPO2-style clipped around ``old_value``."""
    returns = returns.detach()
    unclipped = (new_value - returns).pow(2)
    if not clip:
        return 0.5 * unclipped.mean()
    old_value = old_value.detach()
    v_clipped = old_value + torch.clamp(new_value - old_value, -clip_coef, clip_coef)
    return 0.5 * torch.max(unclipped, (v_clipped - returns).pow(2)).mean()


def answer_loss(answer_logits: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
    """Supervised answer cross-entropy over entries with ``target >= 0``.

    ``answer_logits`` (..., V), ``targets`` (...) int64 with -1 = no supervision.
    With no supervised entry the result is an exact 0 still connected to the graph
    (so ``backward`` works and gives zero gradients).

    A weighted mean over every entry, not a selection of the supervised ones: the same value, with no shape that
    depends on the data, so the update never waits on the device to learn it (a GPU update can be captured).
    """
    flat_logits = answer_logits.reshape(-1, answer_logits.shape[-1])
    flat_targets = targets.reshape(-1).long()
    keep = (flat_targets >= 0).to(flat_logits.dtype)
    ce = F.cross_entropy(flat_logits, flat_targets.clamp(min=0), reduction="none")
    return (ce * keep).sum() / keep.sum().clamp(min=1.0)


def aux_loss(
    aux_logits: torch.Tensor, labels: torch.Tensor, channel_mask: torch.Tensor, balance: str = "none"
) -> torch.Tensor:
    """Per-pixel binary cross-entropy (with logits) averaged over supervised channels only.

    ``aux_logits`` (..., V, h, w) pre-sigmoid conv3 outputs, ``labels`` (..., V, h, w)
    0/1 (any dtype, e.g. uint8), ``channel_mask`` bool (V,): words with an
    auxiliary label (the paper gives none for e.g. 'smallest'/'largest').
    Masked-out channels contribute neither loss nor gradient. Zero (graph kept)
    if no channel is supervised. As in `answer_loss`, a weighted mean (no data-dependent shape).
    ``balance`` (`PPOConfig.aux_balance`): "none", the mean over every entry of a channel (the paper's
    cross-entropy); "word", per channel the mean over its entries labelled 1 and the mean over those labelled 0,
    halved (a channel with entries of one label only in the batch: that label's mean).
    """
    if aux_logits.shape != labels.shape:
        raise ValueError(f"aux_logits {tuple(aux_logits.shape)} vs labels {tuple(labels.shape)}")
    if tuple(channel_mask.shape) != (aux_logits.shape[-3],):
        raise ValueError(f"channel_mask must be ({aux_logits.shape[-3]},), got {tuple(channel_mask.shape)}")
    check_choice("balance", balance, AUX_BALANCES)
    weight = channel_mask.to(device=aux_logits.device, dtype=aux_logits.dtype)[:, None, None]  # (V, 1, 1)
    target = labels.to(aux_logits.dtype)
    bce = F.binary_cross_entropy_with_logits(aux_logits, target, reduction="none")
    if balance == "word":
        dims = tuple(d for d in range(bce.dim()) if d != bce.dim() - 3)  # all but the channel
        pos = (bce * target).sum(dims) / target.sum(dims).clamp(min=1.0)  # (V,)
        neg = (bce * (1 - target)).sum(dims) / (1 - target).sum(dims).clamp(min=1.0)
        sides = (target.sum(dims) > 0).to(bce.dtype) + ((1 - target).sum(dims) > 0).to(bce.dtype)
        per_word = (pos + neg) / sides.clamp(min=1.0)
        mask = weight[:, 0, 0]
        return (per_word * mask).sum() / mask.sum().clamp(min=1.0)
    per_channel = aux_logits[..., :1, :, :].numel()  # entries of one channel
    return (bce * weight).sum() / (weight.sum() * per_channel).clamp(min=1.0)


def explained_variance(values: torch.Tensor, returns: torch.Tensor) -> float:
    """1 - Var[returns - values] / Var[returns] (nan if returns are constant)."""
    var_y = returns.float().var(unbiased=False)
    if var_y.item() == 0.0:
        return float("nan")
    return float(1.0 - (returns.float() - values.float()).var(unbiased=False) / var_y)


def ppo_losses(
    cfg: PPOConfig,
    *,
    logits: torch.Tensor,
    values: torch.Tensor,
    actions: torch.Tensor,
    old_logprobs: torch.Tensor,
    old_values: torch.Tensor,
    advantages: torch.Tensor,
    returns: torch.Tensor,
    answer_logits: torch.Tensor,
    answer_targets: torch.Tensor,
    aux_logits: torch.Tensor | None = None,
    aux_labels: torch.Tensor | None = None,
    aux_channel_mask: torch.Tensor | None = None,
) -> dict[str, torch.Tensor]:
    """Combine all terms for one minibatch.

    Returns a dict with ``policy``, ``value``, ``entropy``, ``answer``, ``aux``
    (only when ``aux_labels`` is given), diagnostics ``approx_kl``, ``clipfrac``,
    and ``total = policy - ent_coef*entropy + vf_coef*value + answer_coef*answer
    (+ aux_coef*aux)``. ``aux_channel_mask`` defaults to all channels.
    """
    adv = advantages.detach()
    if cfg.norm_adv and adv.numel() > 1:
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
    new_logprob = move_logprob(logits, actions)
    pg, approx_kl, clipfrac = policy_loss(new_logprob, old_logprobs, adv, cfg.clip_coef)
    v = value_loss(values, returns, old_values, cfg.clip_coef, cfg.clip_vloss)
    ent = entropy(logits).mean()
    ans = answer_loss(answer_logits, answer_targets)
    total = pg - cfg.ent_coef * ent + cfg.vf_coef * v + cfg.answer_coef * ans
    out = {"policy": pg, "value": v, "entropy": ent, "answer": ans, "approx_kl": approx_kl, "clipfrac": clipfrac}
    if aux_labels is not None:
        if aux_logits is None:
            raise ValueError("aux_labels given but aux_logits is None")
        if aux_channel_mask is None:
            aux_channel_mask = torch.ones(aux_logits.shape[-3], dtype=torch.bool, device=aux_logits.device)
        aux = aux_loss(aux_logits, aux_labels, aux_channel_mask, cfg.aux_balance)
        out["aux"] = aux
        total = total + cfg.aux_coef * aux
    out["total"] = total
    return out


# ---------------------------------------------------------------------------
# Update loop.
# ---------------------------------------------------------------------------

ForwardFn = Callable[[Mapping[str, torch.Tensor], Mapping[str, torch.Tensor], torch.Tensor], Mapping[str, torch.Tensor]]
"""``forward(obs, initial_state, episode_starts)`` replays a (T, b) sequence.

``obs`` values are (T, b, ...), ``initial_state`` values (b, ...), ``episode_starts``
(T, b) bool (reset the recurrent state before those steps). Must return a mapping
with ``logits`` (T, b, 4), ``value`` (T, b), ``answer_logits`` (T, b, V) and, when
auxiliary labels are used, ``aux_logits`` (T, b, V, h, w).
"""


def model_forward(model: torch.nn.Module) -> ForwardFn:
    """``model``'s replay as a ForwardFn: its `ModelOutput` fields as a mapping."""

    def forward(obs, state, episode_starts):
        return vars(model(obs, state, episode_starts)[0])

    return forward


def make_optimizer(params: Iterable[torch.nn.Parameter], cfg: PPOConfig, capturable: bool = False) -> torch.optim.Adam:
    """Adam with the paper's learning rate and our epsilon; ``capturable``: its step count kept on the device, so
    that a CUDA graph can capture its step (emml/rl/graphs.py; the same updates)."""
    return torch.optim.Adam(params, lr=cfg.lr, eps=cfg.adam_eps, capturable=capturable)


def ppo_update(
    forward: ForwardFn,
    optimizer: torch.optim.Optimizer,
    params: Iterable[torch.nn.Parameter],
    buffer: RolloutBuffer,
    cfg: PPOConfig,
    aux_channel_mask: torch.Tensor | None = None,
    use_aux: bool = True,
    generator: torch.Generator | None = None,
) -> dict[str, float]:
    """Run ``cfg.epochs`` epochs of PPO on a filled buffer (after ``compute_returns``).

    Minibatches are disjoint subsets of envs (whole (T,) sequences, so the
    recurrent state is replayed from ``buffer.initial_state``). Auxiliary labels
    are taken from ``buffer.obs["aux"]`` when present and ``use_aux``.
    Returns the mean of each loss term/diagnostic over all minibatch steps, plus
    ``grad_norm`` (pre-clip) and ``explained_variance`` of the rollout.
    """
    params = [p for p in params]
    num_envs = buffer.num_envs
    if num_envs % cfg.minibatches != 0:
        raise ValueError(f"PPOConfig.minibatches={cfg.minibatches} must divide num_envs={num_envs}")
    per_mb = num_envs // cfg.minibatches
    sums: dict[str, torch.Tensor] = {}
    count = 0
    for _ in range(cfg.epochs):
        if cfg.minibatches > 1:
            order = torch.randperm(num_envs, generator=generator).to(buffer.device)
        for start in range(0, num_envs, per_mb):
            # the paper's single batch is a slice (views, no copy of the rollout's frames); minibatches a selection
            idx = slice(None) if cfg.minibatches == 1 else order[start : start + per_mb]
            state = {k: v[idx] for k, v in buffer.initial_state.items()}
            terms = ppo_step(forward, optimizer, params, buffer, state, cfg, aux_channel_mask, use_aux, idx)
            for k, v in terms.items():  # summed on the device: read once, after the last step
                sums[k] = sums.get(k, 0.0) + v.detach()
            count += 1
    stats = {k: float(v) / count for k, v in sums.items()}
    stats["explained_variance"] = explained_variance(buffer.values, buffer.returns)
    return stats


def ppo_step(
    forward: ForwardFn,
    optimizer: torch.optim.Optimizer,
    params: list[torch.nn.Parameter],
    buffer: RolloutBuffer,
    state: Mapping[str, torch.Tensor],
    cfg: PPOConfig,
    aux_channel_mask: torch.Tensor | None = None,
    use_aux: bool = True,
    idx: slice | torch.Tensor = slice(None),
) -> dict[str, torch.Tensor]:
    """One optimiser step of `ppo_update` on the actors ``idx`` of the buffer (all: the paper's single batch), their
    sequences replayed from ``state``: the loss terms and ``grad_norm`` (pre-clip), as tensors on the device.

    No host sync and no shape that depends on the data: with the whole batch it can be captured as one CUDA graph
    (emml/rl/graphs.py), reading the buffer's storage and ``state`` in place."""
    labels_all = buffer.obs.get("aux") if use_aux else None
    obs = {k: v[:, idx] for k, v in buffer.obs.items()}
    out = forward(obs, state, buffer.episode_starts[:, idx])
    terms = ppo_losses(
        cfg,
        logits=out["logits"],
        values=out["value"],
        actions=buffer.actions[:, idx],
        old_logprobs=buffer.logprobs[:, idx],
        old_values=buffer.values[:, idx],
        advantages=buffer.advantages[:, idx],
        returns=buffer.returns[:, idx],
        answer_logits=out["answer_logits"],
        answer_targets=buffer.answer_targets[:, idx],
        aux_logits=out.get("aux_logits") if labels_all is not None else None,
        aux_labels=labels_all[:, idx] if labels_all is not None else None,
        aux_channel_mask=aux_channel_mask,
    )
    optimizer.zero_grad(set_to_none=True)
    terms["total"].backward()
    terms["grad_norm"] = torch.nn.utils.clip_grad_norm_(params, cfg.max_grad_norm)
    optimizer.step()
    return {k: v.detach() for k, v in terms.items()}
