"""`TrainConfig.cuda_graphs`: acting and the PPO update replayed as CUDA graphs (issue 51, item 1).

At the quick profile a GPU spends most of a run launching kernels: one acting step runs a few hundred small kernels
for 4 observations (docs/throughput.md, "A GPU node"). A CUDA graph records those launches once and replays them as
one. What is captured:

- **Acting** (`act`): the model's forward for one env group, with the recurrent state and the episode starts as
  inputs. The inputs are copied into the graph's own tensors, the graph replayed, its outputs read: the sampler
  stores what it keeps before the next call overwrites them. The moves are sampled outside the graph, from the
  default generator, so they are drawn exactly as the plain path draws them (a sample inside a graph would replay
  one frozen draw).
- **The update** (`Graphs.step`): one optimiser step on the whole rollout (the paper's single batch:
  `emml.rl.ppo.ppo_step`, `emml.rl.packed.packed_ppo_step`), reading the rollout buffer's storage in place and the
  initial recurrent state from its own copy; replayed once per epoch. Adam keeps its step count on the device
  (`capturable`).

Weights are changed in place (Adam's step, `load_state_dict`), so a replay reads the current ones. What a graph
freezes is the Python around the kernels: the input shapes and a model's switches (`EmmlModel.trace_key`: the
answer loss's warm-up, the conv precision) key the graphs, and a new key is captured anew. Before it captures, CUDA
runs the call a few times on a side stream; for the update those runs step the optimizer, so the parameters and the
optimizer's state are put back as they were, in place, before the first replay.

On a CPU there are no CUDA graphs: the same calls run uncaptured on the same fixed tensors, warm-up and restore
included. That path is what the CPU tests compare with the plain one (tests/rl/test_graphs.py); the capture itself
is tested where CUDA is (the GPU check runs those tests first: scripts/gpu-check).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Any

import torch
from torch import Tensor

WARMUP = 3
"""Calls before a capture (CUDA's side-stream warm-up: lazy initialisations and allocator state happen there)."""


class Captured:
    """``fn(inputs)`` replayed on fixed input tensors: a CUDA graph where ``capture``, else the same call uncaptured.

    ``kept``: the tensors the call changes in place (parameters, optimizer state) and how to put them back after
    the warm-up (`Kept`); None for a call without side effects (acting)."""

    def __init__(self, fn: Callable[[dict[str, Tensor]], Any], capture: bool, kept: Kept | None = None) -> None:
        self.fn, self.capture, self.kept = fn, capture, kept
        self.inputs: dict[str, Tensor] | None = None
        self.outputs: Any = None
        self.graph: torch.cuda.CUDAGraph | None = None

    def __call__(self, inputs: Mapping[str, Tensor]) -> Any:
        """The call on ``inputs`` (copied into the fixed tensors); its outputs stay valid until the next call."""
        if self.inputs is None:
            self._capture(inputs)
        else:
            for k, v in inputs.items():
                self.inputs[k].copy_(v, non_blocking=True)
        if self.graph is not None:
            self.graph.replay()
        else:
            self.outputs = self.fn(self.inputs)
        return self.outputs

    def _capture(self, inputs: Mapping[str, Tensor]) -> None:
        self.inputs = {k: v.detach().clone() for k, v in inputs.items()}
        before = self.kept.save() if self.kept is not None else None
        if self.capture:
            side = torch.cuda.Stream()
            side.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(side):
                for _ in range(WARMUP):
                    self.fn(self.inputs)
            torch.cuda.current_stream().wait_stream(side)
            self.graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(self.graph):
                self.outputs = self.fn(self.inputs)
        else:
            for _ in range(WARMUP):  # the same side effects as on a GPU, undone the same way
                self.fn(self.inputs)
        if self.kept is not None:
            self.kept.restore(before)


class Kept:
    """Parameters and an optimizer's state, saved before a captured update's warm-up and put back after it, in place
    (a captured graph holds those very tensors). Optimizer state made during the warm-up (Adam's moments and step
    count on a first update) is put back to what a fresh optimizer starts from: zeros."""

    def __init__(self, params: Iterable[Tensor], optimizer: torch.optim.Optimizer) -> None:
        self.params, self.optimizer = list(params), optimizer

    def save(self) -> tuple[list[Tensor], dict[int, dict[str, Tensor]]]:
        with torch.no_grad():
            params = [p.detach().clone() for p in self.params]
            state = {
                i: {k: v.clone() for k, v in self.optimizer.state[p].items() if isinstance(v, Tensor)}
                for i, p in enumerate(self.params)
            }
        return params, state

    def restore(self, saved: tuple[list[Tensor], dict[int, dict[str, Tensor]]]) -> None:
        params, state = saved
        with torch.no_grad():
            for i, (p, before) in enumerate(zip(self.params, params)):
                p.copy_(before)
                for k, v in self.optimizer.state[p].items():
                    if isinstance(v, Tensor):
                        v.copy_(state[i][k]) if k in state[i] else v.zero_()


class Graphs:
    """The captured calls of one training loop, keyed by what each freezes; made on first use.

    ``device``: CUDA captures; any other device runs the same fixed-tensor calls uncaptured."""

    def __init__(self, device: torch.device | str) -> None:
        self.capture = torch.device(device).type == "cuda"
        self.calls: dict[tuple, Captured] = {}

    def run(self, key: tuple, fn: Callable[[dict[str, Tensor]], Any], inputs: Mapping[str, Tensor], kept=None) -> Any:
        call = self.calls.get(key)
        if call is None:
            call = self.calls[key] = Captured(fn, self.capture, kept)
        return call(inputs)

    def step(
        self,
        key: tuple,
        step: Callable[[dict[str, Tensor]], Any],
        state: Mapping[str, Tensor],
        epochs: int,
        kept: Kept,
    ) -> list[Any]:
        """``epochs`` replays of an optimiser step ``step(state)`` (reading the rollout in place); each replay's
        outputs, copied (the next replay overwrites them)."""
        outs = []
        for _ in range(epochs):
            out = self.run(key, step, state, kept)
            outs.append(_copied(out))
        return outs


def captures(cfg) -> bool:
    """Whether the run's `TrainConfig` captures CUDA graphs: `cuda_graphs` on a CUDA device (its optimizer is then
    made capturable: `emml.rl.ppo.make_optimizer`)."""
    return bool(cfg.cuda_graphs) and torch.device(cfg.device).type == "cuda"


def mean_stats(outs: list[dict[str, Tensor]]) -> dict[str, float]:
    """The mean of each term over the replays of an update (`Graphs.step`), read from the device once."""
    keys = outs[0].keys()
    stacked = torch.stack([torch.stack([o[k].float() for k in keys]) for o in outs]).mean(0).tolist()
    return dict(zip(keys, stacked))


def _copied(out: Any) -> Any:
    if isinstance(out, Tensor):
        return out.clone()
    if isinstance(out, dict):
        return {k: _copied(v) for k, v in out.items()}
    if isinstance(out, (list, tuple)):
        return type(out)(_copied(v) for v in out)
    return out


def acting(graphs: Graphs | None, model, obs: Mapping[str, Tensor], state: Mapping[str, Tensor], episode_start: Tensor):
    """One acting step, ``model(obs, state, episode_start)``: the plain call without ``graphs``, else `act`."""
    if graphs is None:
        return model(obs, state, episode_start)
    return act(graphs, model, obs, state, episode_start)


def act(graphs: Graphs, model, obs: Mapping[str, Tensor], state: Mapping[str, Tensor], episode_start: Tensor):
    """``model(obs, state, episode_start)`` (acting, no gradients) through a captured graph: the same
    (`ModelOutput`, new state), whose tensors the next call overwrites."""
    inputs = {**{f"obs/{k}": v for k, v in obs.items()}, **{f"state/{k}": v for k, v in state.items()}}
    inputs["episode_start"] = episode_start
    key = ("act", id(model), model.trace_key(), *sorted((k, tuple(v.shape), str(v.dtype)) for k, v in inputs.items()))

    def forward(x: dict[str, Tensor]):
        obs = {k[4:]: v for k, v in x.items() if k.startswith("obs/")}
        state = {k[6:]: v for k, v in x.items() if k.startswith("state/")}
        return model(obs, state, x["episode_start"])

    return graphs.run(key, forward, inputs)
