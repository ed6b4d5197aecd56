"""Several runs of one architecture trained as one model: their parameters stacked along a run axis, every forward
pass one `torch.func.vmap` over that axis, so that one kernel serves all runs (issue 19, item 3).

Layout. The runs' actors are interleaved: actor ``j = b * N + r`` is actor ``b`` of run ``r``, so any contiguous
slice of actors whose length is a multiple of N (a rollout's env group, a minibatch) holds whole runs side by side,
and a (T, B·N, ...) batch views as (T, B, N, ...) without a copy.

The update (`packed_ppo_update`) is each run's own PPO update (`emml.rl.ppo`): the runs' losses are summed, which
gives each run's parameters exactly its own gradient (the parameters are disjoint); the gradient norm is clipped
per run, as `clip_grad_norm_` does for one; Adam is elementwise, so one Adam over the stacked tensors is N Adams.
`unstack` gives run r back as a plain model, and `optimizer_state` its optimizer's state in the plain format, so a
packed run's checkpoint is an ordinary one (tests/rl/test_packed.py checks outputs and one update against
separate runs).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence

import torch
from torch import Tensor, nn
from torch.func import functional_call, stack_module_state, vmap

from emml.models.policy import EmmlModel, ModelOutput
from emml.rl.ppo import PPOConfig, explained_variance, ppo_losses
from emml.rl.rollout import RolloutBuffer


def _split(x: Tensor, n: int, dim: int) -> Tensor:
    """View dimension ``dim`` of length B·N as (B, N): the interleaved layout."""
    return x.unflatten(dim, (x.shape[dim] // n, n))


class StackedModels(nn.Module):
    """N `EmmlModel`s of one architecture: parameters (N, ...) and one vmapped forward.

    ``forward`` has the plain model's interface over interleaved actors: obs (T, B·N, ...), state (B·N, ...),
    episode_start (T, B·N), returning a `ModelOutput` over (T, B·N) and the new state. ``forward_runs`` returns
    the outputs with a leading run axis instead, (N, T, B, ...), for the per-run losses.
    """

    def __init__(self, models: Sequence[EmmlModel]) -> None:
        super().__init__()
        if len(models) < 1:
            raise ValueError("StackedModels needs at least one model")
        specs = {repr((m.cfg, m.vocab_size, m.height, m.width, m.policy.max_steps)) for m in models}
        if len(specs) != 1:
            raise ValueError("packed runs must share the architecture, vocabulary size and input size")
        if any(m.detector is not None for m in models):
            raise ValueError("packed runs cannot carry transfer detectors (emml/eval/transfer.py)")
        if any(True for _ in models[0].buffers()):
            raise ValueError("packed runs stack parameters only; this model has buffers")
        self.runs = len(models)
        template = copy.deepcopy(models[0]).vmappable()
        params, _ = stack_module_state(list(models))  # copies: the models given stay as they are
        self.stacked = nn.ParameterDict({k.replace(".", "/"): nn.Parameter(v) for k, v in params.items()})
        self.names = list(params)
        """Parameter names of the plain model, in its `parameters()` order."""
        self.template = [template.to("meta")]  # a list: not a submodule, its meta weights are never used

    # --- the plain model's interface ------------------------------------------------------------------------------
    @property
    def cfg(self):
        return self.template[0].cfg

    @property
    def reads_labels(self) -> bool:
        return self.template[0].reads_labels

    def initial_state(self, batch_size: int, device=None) -> dict[str, Tensor]:
        return self.template[0].initial_state(batch_size, device=device)

    def trace_key(self) -> tuple:
        return self.template[0].trace_key()

    def capturable(self) -> StackedModels:
        """Already: its template is `vmappable`, which reads nothing on the host (emml/rl/graphs.py)."""
        return self

    def acting_state(self, state: dict[str, Tensor]) -> dict[str, Tensor]:
        """``state`` itself: stacked runs recompute a frame window's conv at each step (no acting cache)."""
        return state

    def replay_state(self, state: dict[str, Tensor]) -> dict[str, Tensor]:
        return self.template[0].replay_state(state)

    def forward_runs(self, obs: dict[str, Tensor], state: dict[str, Tensor], episode_start: Tensor):
        """Interleaved inputs -> ({ModelOutput field: (N, T, B, ...)}, new state {key: (N, B, ...)})."""
        n = self.runs
        params = dict(zip(self.names, self.parameters_in_order()))
        template = self.template[0]

        def one(p, o, s, e):
            out, new = functional_call(template, p, (o, s, e))
            return {k: v for k, v in vars(out).items() if v is not None}, new  # vmap returns tensors only

        obs_r = {k: _split(v, n, 1) for k, v in obs.items()}
        state_r = {k: _split(v, n, 0) for k, v in state.items()}
        out, new = vmap(one, in_dims=(0, 2, 1, 2))(params, obs_r, state_r, _split(episode_start, n, 1))
        return {f: out.get(f) for f in ModelOutput.__dataclass_fields__}, new

    def forward(self, obs, state, episode_start) -> tuple[ModelOutput, dict[str, Tensor]]:
        out, new = self.forward_runs(obs, state, episode_start)
        fields = {k: None if v is None else _interleave(v) for k, v in out.items()}
        return ModelOutput(**fields), {k: v.transpose(0, 1).flatten(0, 1) for k, v in new.items()}

    # --- back to plain runs -----------------------------------------------------------------------------------------
    def unstack(self, run: int) -> EmmlModel:
        """Run ``run`` as a plain model (a copy) on the stacked parameters' device."""
        template = self.template[0]
        model = EmmlModel(template.cfg, template.vocab_size, template.height, template.width, template.policy.max_steps)
        params = self.parameters_in_order()
        model.load_state_dict({name: p[run].detach() for name, p in zip(self.names, params)})
        return model.to(params[0].device)

    def load_run(self, run: int, state_dict: dict[str, Tensor]) -> None:
        """Put a plain model's ``state_dict`` into slot ``run`` (resuming a run from its checkpoint)."""
        with torch.no_grad():
            for name, p in zip(self.names, self.parameters_in_order()):
                p[run].copy_(state_dict[name])

    def parameters_in_order(self) -> list[nn.Parameter]:
        """The stacked parameters in the plain model's `parameters()` order (the optimizer's order)."""
        return [self.stacked[name.replace(".", "/")] for name in self.names]


def _interleave(x: Tensor) -> Tensor:
    """(N, T, B, ...) -> (T, B·N, ...): the run axis back inside the actors."""
    return x.movedim(0, 2).flatten(1, 2)


def optimizer_state(optimizer: torch.optim.Optimizer, run: int) -> dict:
    """Run ``run``'s slice of an optimizer over the stacked parameters, as the `state_dict` of the same optimizer
    over one plain model's parameters (same order): what its checkpoint stores."""
    full = optimizer.state_dict()
    state = {}
    for index, entry in full["state"].items():
        state[index] = {k: (v if k == "step" or v.dim() == 0 else v[run].clone()) for k, v in entry.items()}
    return {"state": state, "param_groups": copy.deepcopy(full["param_groups"])}


def load_optimizer_state(optimizer: torch.optim.Optimizer, run: int, saved: dict) -> None:
    """Put a plain run's optimizer ``saved`` state into slot ``run`` of the stacked optimizer (resume)."""
    params = optimizer.param_groups[0]["params"]
    for index, entry in saved["state"].items():
        target = optimizer.state[params[int(index)]]
        for k, v in entry.items():
            if k == "step" or v.dim() == 0:
                target[k] = v.clone() if k not in target else target[k]
            else:
                if k not in target:
                    target[k] = torch.zeros_like(params[int(index)])
                target[k][run].copy_(v)


def clip_grad_norm_per_run(params: Sequence[Tensor], max_norm: float) -> Tensor:
    """`clip_grad_norm_` for each run's slice (dim 0) of stacked parameters; returns the (N,) pre-clip norms."""
    grads = [p.grad for p in params if p.grad is not None]
    norms = torch.stack([g.flatten(1).pow(2).sum(1) for g in grads]).sum(0).sqrt()  # (N,)
    coef = (max_norm / (norms + 1e-6)).clamp(max=1.0)
    for g in grads:
        g.mul_(coef.view(-1, *([1] * (g.dim() - 1))))
    return norms


def packed_ppo_update(
    stacked: StackedModels,
    optimizer: torch.optim.Optimizer,
    buffer: RolloutBuffer,
    cfg: PPOConfig,
    aux_channel_mask: Tensor | None = None,
    use_aux: bool = True,
) -> list[dict[str, float]]:
    """`emml.rl.ppo.ppo_update` for every packed run at once, on a buffer of interleaved actors (after
    ``compute_returns``, which is per actor and so per run already); one stats dict per run.

    The paper's protocol (one batch, ``cfg.minibatches == 1``) only: a packed run's minibatch split would draw
    another permutation than the run alone."""
    if cfg.minibatches != 1:
        raise ValueError(
            f"packed runs train with PPOConfig.minibatches=1 (the paper's single batch), got {cfg.minibatches}"
        )
    n = stacked.runs
    sums = [dict() for _ in range(n)]
    for _ in range(cfg.epochs):
        for r, terms in enumerate(
            packed_ppo_step(stacked, optimizer, buffer, buffer.initial_state, cfg, aux_channel_mask, use_aux)
        ):
            for k, v in terms.items():  # summed on the device and read once, after the last epoch (as ppo_update)
                sums[r][k] = sums[r].get(k, 0.0) + v
    stats = []
    for r in range(n):
        s = {k: float(v) / cfg.epochs for k, v in sums[r].items()}
        s["explained_variance"] = run_explained_variance(buffer, n, r)
        stats.append(s)
    return stats


def run_explained_variance(buffer: RolloutBuffer, n: int, r: int) -> float:
    """Run r's explained variance of its rollout's returns (`emml.rl.ppo.explained_variance`)."""
    return explained_variance(_run_slice(buffer.values, n, r), _run_slice(buffer.returns, n, r))


def _run_slice(x: Tensor, n: int, r: int) -> Tensor:
    """Run r's actors of an interleaved (T, B·N, ...) tensor."""
    return _split(x, n, 1)[:, :, r]


def packed_ppo_step(
    stacked: StackedModels,
    optimizer: torch.optim.Optimizer,
    buffer: RolloutBuffer,
    state: dict[str, Tensor],
    cfg: PPOConfig,
    aux_channel_mask: Tensor | None = None,
    use_aux: bool = True,
) -> list[dict[str, Tensor]]:
    """One optimiser step of every packed run on the whole buffer, replayed from ``state``: per run its loss terms
    and ``grad_norm`` (pre-clip), tensors on the device. As `emml.rl.ppo.ppo_step`, capturable as one CUDA graph
    (emml/rl/graphs.py)."""
    n = stacked.runs
    params = stacked.parameters_in_order()
    labels_all = buffer.obs.get("aux") if use_aux else None
    out, _ = stacked.forward_runs(buffer.obs, state, buffer.episode_starts)
    total = 0.0
    per_run = []
    for r in range(n):
        terms = ppo_losses(
            cfg,
            logits=out["logits"][r],
            values=out["value"][r],
            actions=_run_slice(buffer.actions, n, r),
            old_logprobs=_run_slice(buffer.logprobs, n, r),
            old_values=_run_slice(buffer.values, n, r),
            advantages=_run_slice(buffer.advantages, n, r),
            returns=_run_slice(buffer.returns, n, r),
            answer_logits=out["answer_logits"][r],
            answer_targets=_run_slice(buffer.answer_targets, n, r),
            aux_logits=out["aux_logits"][r] if labels_all is not None else None,
            aux_labels=_run_slice(labels_all, n, r) if labels_all is not None else None,
            aux_channel_mask=aux_channel_mask,
        )
        total = total + terms["total"]
        per_run.append(terms)
    optimizer.zero_grad(set_to_none=True)
    total.backward()
    norms = clip_grad_norm_per_run(params, cfg.max_grad_norm)
    optimizer.step()
    return [
        {**{k: v.detach() for k, v in terms.items()}, "grad_norm": norms[r].detach()} for r, terms in enumerate(per_run)
    ]
