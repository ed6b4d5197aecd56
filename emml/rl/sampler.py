"""Rollout collection for the trainer: the 8 actors of the paper's protocol (Appendix A), double-buffered.

The actors are split into ``groups`` vector envs (worker processes, uint8 shared-memory observations). At each
step the policy acts for one group and sends its actions off, and while that group's workers simulate, the
policy acts for the next group (double buffering). Nothing else changes: every action comes from the same
parameters (the rollout ends before the update starts, so PPO stays strictly on-policy) and every actor steps in
order, so the stored rollout is the one the lockstep loop (``groups=1``) would store under the same seeds, up to
the order in which action samples are drawn.

On a GPU, observations go through pinned host buffers and non-blocking copies.

Bookkeeping per actor: training-episode success per task (last 100), and the episodes dropped because an engine
died mid-episode (`emml.envs.vector` restarts it; the episode ends there as truncated and is not scored). When a
whole worker process dies, its group's vector env is started afresh (every episode of the group is dropped and
counted); `max_engine_restarts` such deaths in a row, less than `engine_restart_window` steps apart, end the run.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections import deque

import numpy as np
import torch
from torch import Tensor

from emml.config.schema import TrainConfig
from emml.envs.doom import ANSWER
from emml.envs.engine import RestartBudget, WorkerDied
from emml.envs.vector import make_vector_env
from emml.eval.evaluate import obs_to_torch
from emml.rl.graphs import Graphs, acting

log = logging.getLogger(__name__)


class Sampler:
    """Owns the actors' envs, their current observations and the policy's recurrent state between rollouts."""

    def __init__(self, cfg: TrainConfig, device: torch.device, runs: int = 1, graphs: Graphs | None = None):
        self.cfg = cfg
        self.graphs = graphs
        """Acting through captured CUDA graphs (`TrainConfig.cuda_graphs`, emml/rl/graphs.py); None: plain calls."""
        self.device = device
        self.groups = cfg.env_groups
        self.runs = runs
        """Packed runs (emml/rl/packed.py) whose actors are interleaved: actor j is actor j // runs of run j % runs."""
        self.num_envs = B = cfg.num_envs * runs
        if self.groups < 1 or cfg.num_envs % self.groups:
            raise ValueError(f"env_groups={self.groups} must divide num_envs={cfg.num_envs}")
        size = B // self.groups
        self.slices = [slice(g * size, (g + 1) * size) for g in range(self.groups)]
        self.venvs = []
        try:
            for _ in range(self.groups):
                self.venvs.append(self._make_group())
        except BaseException:
            self.close(abort=True)
            raise
        self.recent_by_run = [{0: deque(maxlen=100), 1: deque(maxlen=100)} for _ in range(runs)]
        """Training-episode success per run and task id (0 SGN, 1 EQA), last 100 episodes."""
        self.recent = self.recent_by_run[0]
        self.dropped_episodes = 0
        """Episodes cut short by an engine or worker death (the engine or group was restarted; not scored)."""
        self.workers = RestartBudget(cfg.max_engine_restarts, cfg.engine_restart_window, "env worker", WorkerDied)
        """Groups restarted because one of their worker processes died (``.restarts``)."""
        self.timing = {"simulate": 0.0, "infer": 0.0}
        """Seconds the learner waited on the envs / spent acting in the last `collect`."""
        self.acting_threads = cfg.acting_threads
        self._pinned = self.device.type == "cuda"
        self._staging: dict[int, dict[str, torch.Tensor]] = {}

    def _make_group(self):
        cfg = self.cfg
        env_cfg = cfg.env
        if cfg.model_options.get("control") == "target_mask":  # the diagnostic control reads the referent's cells
            env_cfg = dataclasses.replace(env_cfg, target_in_obs=True)
        return make_vector_env(
            env_cfg,
            self.num_envs // self.groups,
            asynchronous=cfg.asynchronous,
            copy=False,
            max_restarts=cfg.max_engine_restarts,
            restart_window=cfg.engine_restart_window,
            envs_per_worker=cfg.envs_per_worker,
        )

    # --- lifecycle --------------------------------------------------------------------------------------------
    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        self.close(abort=exc_type is not None)
        return False

    def close(self, abort: bool = False) -> None:
        """Close every group's workers (``abort``: terminate them without talking: see vector.abort)."""
        for venv in self.venvs:
            if abort and hasattr(venv, "abort"):
                venv.abort()
            else:
                venv.close()

    @property
    def single_observation_space(self):
        return self.venvs[0].single_observation_space

    def reset(self, model, seed: int | list[int]) -> None:
        """Start an episode in every actor (actor i gets seed ``seed + i``, or ``seed[i]`` from a list) and zero
        the recurrent state."""
        self._seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, int) else list(seed)
        if len(self._seeds) != self.num_envs:
            raise ValueError(f"{len(self._seeds)} seeds for {self.num_envs} actors")
        self.obs, self.answers, self.tasks = [None] * self.groups, [None] * self.groups, [None] * self.groups
        for g in range(self.groups):
            self._reset_group(g, 0)
        self.state = model.initial_state(self.num_envs, device=self.device)
        self.episode_start = torch.ones(self.num_envs, dtype=torch.bool, device=self.device)

    def _reset_group(self, g: int, offset: int) -> None:
        sl = self.slices[g]
        obs, info = self.venvs[g].reset(seed=[self._seeds[i] + offset for i in range(sl.start, sl.stop)])
        self.obs[g] = obs
        self.answers[g], self.tasks[g] = np.asarray(info["answer"]), np.asarray(info["task"])

    def _restart_group(self, g: int, error: Exception) -> None:
        """A worker of group g died: end the group (and the engine the dead worker left), start it afresh."""
        self.workers.death(error)
        self.venvs[g].abort()
        self.venvs[g] = self._make_group()
        self._reset_group(g, 1_000_003 * self.workers.restarts)  # fresh episodes, reproducibly

    # --- one rollout ------------------------------------------------------------------------------------------
    @torch.no_grad()
    def collect(self, model, buffer) -> None:
        """Fill ``buffer`` with ``num_steps`` steps of every actor, acting with ``model`` (sampled moves, argmax
        answer word), and leave the observation after the last step in ``self.obs`` for bootstrapping."""
        T = self.cfg.num_steps
        buffer.set_initial_state(model.replay_state(self.state))
        self.state = model.acting_state(self.state)  # a frame window's conv cache, under the weights of this rollout
        self.timing = dict.fromkeys(self.timing, 0.0)
        pending = [False] * self.groups
        learner_threads = torch.get_num_threads()
        if self.acting_threads:
            torch.set_num_threads(self.acting_threads)
        try:
            for t in range(T):
                for g in range(self.groups):
                    if pending[g]:
                        self._receive(g, t - 1, buffer)
                    self._act(g, t, model, buffer)
                    pending[g] = True
            for g in range(self.groups):
                self._receive(g, T - 1, buffer)
        finally:
            torch.set_num_threads(learner_threads)

    def last_value(self, model) -> torch.Tensor:
        """V(s_T) of every actor, for GAE (the state is not advanced)."""
        with torch.no_grad():
            out, _ = model(self._to_torch(-1, _stack(self.obs)), self.state, self.episode_start.unsqueeze(0))
        return out.value[0]

    def _act(self, g: int, t: int, model, buffer) -> None:
        sl = self.slices[g]
        t0 = time.perf_counter()
        obs_t = self._to_torch(g, self.obs[g])
        state = {k: v[sl] for k, v in self.state.items()}
        # through a graph, the outputs are the graph's: read (sampled, stored) below, before the next group's call
        out, state = acting(self.graphs, model, obs_t, state, self.episode_start[sl].unsqueeze(0))
        for k, v in state.items():
            self.state[k][sl] = v
        move, log_prob = sample_moves(out.logits[0])
        word = out.answer_logits[0].argmax(-1)
        action = torch.stack([move, word], dim=1).cpu().numpy()  # (waits for the device: staging reusable after)
        target = np.where(self.tasks[g] == 1, self.answers[g], -1)  # answer CE on EQA episodes (§3.3)
        if self.cfg.answer_supervision == "answer_steps":
            target = np.where(action[:, 0] == ANSWER, target, -1)
        buffer.insert_policy(
            t,
            {k: v[0] for k, v in obs_t.items()},
            move,
            torch.as_tensor(target),
            log_prob,
            out.value[0],
            self.episode_start[sl],
            envs=sl,
        )
        try:
            self.venvs[g].step_async(action)
        except (BrokenPipeError, EOFError, ConnectionResetError):
            pass  # the worker is gone: step_wait tells which
        self.timing["infer"] += time.perf_counter() - t0

    def _receive(self, g: int, t: int, buffer) -> None:
        sl = self.slices[g]
        t0 = time.perf_counter()
        try:
            obs, reward, terminated, truncated, info = self.venvs[g].step_wait()
        except (WorkerDied, BrokenPipeError, EOFError, ConnectionResetError) as e:
            self._restart_group(g, e)  # every episode of the group ends here: truncated, reward 0, not scored
            n = sl.stop - sl.start
            log.warning("env worker of group %d died (%s): group restarted, %d episodes dropped", g, e, n)
            buffer.insert_outcome(t, torch.zeros(n), torch.ones(n, dtype=torch.bool), envs=sl)
            self.dropped_episodes += n
            self.episode_start[sl] = True
            self.timing["simulate"] += time.perf_counter() - t0
            return
        self.timing["simulate"] += time.perf_counter() - t0
        self.workers.step()
        done = np.logical_or(terminated, truncated)
        buffer.insert_outcome(t, torch.as_tensor(reward, dtype=torch.float32), torch.as_tensor(done), envs=sl)
        if done.any():
            final = info["final_info"]
            dropped = final.get("engine_restart", np.zeros(len(done), dtype=bool))
            for i in np.flatnonzero(done):
                if dropped[i]:
                    self.dropped_episodes += 1
                    log.warning(
                        "ViZDoom engine of actor %d died: restarted, its episode dropped (%d dropped in this run)",
                        sl.start + i,
                        self.dropped_episodes,
                    )
                else:
                    run = self.recent_by_run[(sl.start + i) % self.runs]
                    run[int(final["task"][i])].append(float(final["success"][i]))
        self.obs[g] = obs
        self.answers[g], self.tasks[g] = np.asarray(info["answer"]), np.asarray(info["task"])
        self.episode_start[sl] = torch.as_tensor(done, device=self.device)

    def _to_torch(self, g: int, obs: dict) -> dict[str, torch.Tensor]:
        """Numpy batch (B, ...) → tensors (1, B, ...) on the device; on a GPU through per-group pinned buffers."""
        if not self._pinned:
            return obs_to_torch(obs, self.device)
        out = {}
        staging = self._staging.setdefault(g, {})
        for k, v in obs.items():
            src = torch.as_tensor(np.asarray(v))
            buf = staging.get(k)
            if buf is None or buf.shape != src.shape:
                buf = staging[k] = torch.empty(src.shape, dtype=src.dtype).pin_memory()
            buf.copy_(src)
            out[k] = buf.to(self.device, non_blocking=True).unsqueeze(0)
        return out


def sample_moves(logits: Tensor) -> tuple[Tensor, Tensor]:
    """A move per row of ``logits`` (B, moves) and its log-probability: the ops of
    `torch.distributions.Categorical(logits=logits)`'s ``sample()`` and ``log_prob()``, so the same draws and values
    bit for bit (tested), without building a distribution object and validating its arguments at every step."""
    logits = logits - logits.logsumexp(dim=-1, keepdim=True)
    move = torch.multinomial(torch.softmax(logits, dim=-1), 1, True)[:, 0]
    return move, logits.gather(-1, move.unsqueeze(-1))[:, 0]


def _stack(parts: list[dict]) -> dict:
    if len(parts) == 1:
        return parts[0]
    return {k: np.concatenate([np.asarray(p[k]) for p in parts]) for k in parts[0]}
