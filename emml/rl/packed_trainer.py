"""Several seeds of one run trained in one process (issue 19, item 3): one stacked model (emml/rl/packed.py), one
sampler over every run's actors (interleaved), one update for all; each run keeps its own run directory,
checkpoint, MLflow run, evaluations and results row, exactly as `emml.rl.trainer` writes them.

Each run starts from the parameters its plain run would start from (its seed, its checkpoint) and its actors get
the env seeds its plain run would give them; its update is its own (tested in tests/rl/test_packed.py). What
differs from training the runs apart: the action samples come from one generator for all runs, and the global RNG
state saved with each checkpoint is the pack's. A packed run's checkpoint is an ordinary one: `emml train` resumes
it alone, and the pack resumes from ordinary checkpoints when they are all at the same update.
"""

from __future__ import annotations

import dataclasses
import time
from contextlib import ExitStack

import numpy as np
import torch

from emml.config import TrainConfig
from emml.envs.labels import channel_mask
from emml.rl.packed import StackedModels, load_optimizer_state, optimizer_state, packed_ppo_update
from emml.rl.ppo import make_optimizer
from emml.rl.precision import conv_precision
from emml.rl.rollout import RolloutBuffer
from emml.rl.sampler import Sampler
from emml.rl.trainer import RunResult, Trainer, _dtype, update_metrics
from emml.runlock import hold_run
from emml.tracking import Tracker

SEED_ONLY = "seed"
"""The one config field in which packed runs may differ."""


def check_packable(cfgs: list[TrainConfig]) -> None:
    """Refuse, before any compute, runs that cannot share one stacked model and one sampler."""
    if len(cfgs) < 2:
        raise ValueError("packing needs at least two runs (seeds)")
    seeds = [c.seed for c in cfgs]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"packed runs need distinct seeds, got {seeds}")
    first = {k: v for k, v in cfgs[0].to_dict().items() if k != SEED_ONLY}
    for c in cfgs[1:]:
        other = {k: v for k, v in c.to_dict().items() if k != SEED_ONLY}
        diff = sorted(k for k in first.keys() | other.keys() if first.get(k) != other.get(k))
        if diff:
            raise ValueError(f"packed runs may differ only in seed; these differ: {', '.join(diff)}")
    if cfgs[0].ppo.minibatches != 1:
        raise ValueError(f"packed runs train with ppo.minibatches=1 (the paper's), got {cfgs[0].ppo.minibatches}")


class PackedTrainer:
    def __init__(self, cfgs: list[TrainConfig], trackers: list[Tracker] | None = None, quiet: bool = False):
        check_packable(cfgs)
        self.trainers = [Trainer(c, tracker=trackers[i] if trackers else None, quiet=quiet) for i, c in enumerate(cfgs)]
        self.cfg = self.trainers[0].cfg
        self.device = self.trainers[0].device
        self.quiet = quiet

    def train(self) -> list[RunResult]:
        with ExitStack() as held:
            for t in self.trainers:  # every run's lock, before any checkpoint is read
                held.enter_context(hold_run(t.dir))
            return self._train()

    def _train(self) -> list[RunResult]:
        saved = [t.saved() for t in self.trainers]  # each checkpoint read (and checked) once here
        finished = [t.finished(s) for t, s in zip(self.trainers, saved)]
        if any(finished):  # finished runs are skipped (and recorded); the rest train packed, or alone if one
            left = [t for t, f in zip(self.trainers, finished) if not f]
            rest = iter(
                []
                if not left
                else [left[0].train()]
                if len(left) == 1
                else PackedTrainer([t.cfg for t in left], [t.tracker for t in left], self.quiet).train()
            )
            return [t.open() if f else next(rest) for t, f in zip(self.trainers, finished)]
        updates = {s["update"] if s else 0 for s in saved}
        if len(updates) != 1:
            raise ValueError(
                f"packed runs must resume from the same update, found updates {sorted(updates)}: train them apart "
                "(emml train --seed N) to the same update, or start them afresh"
            )
        try:  # from the first MLflow run started (open), a failure ends every started run, never leaves it RUNNING
            opened = [t.open(build=False) for t in self.trainers]
            stacked = StackedModels([o[0] for o in opened]).to(self.device)
            optimizer = make_optimizer(stacked.parameters_in_order(), self.cfg.ppo)
            for r, o in enumerate(opened):
                if o[1] is not None:
                    load_optimizer_state(optimizer, r, o[1])
            update, frames = opened[0][2], opened[0][3]
            finals = self._loop(stacked, optimizer, update, frames)
        except BaseException as e:  # KILLED on Ctrl-C or a termination signal, else FAILED (Tracker.abort)
            for t in self.trainers:
                t.tracker.abort(e)
            raise
        results = []
        for t, (metrics, frames), o in zip(self.trainers, finals, opened):
            t.tracker.finish("FINISHED")
            results.append(RunResult(t.dir, t.tracker.run_id, frames, metrics, resumed=o[4]))
        return results

    def _checkpoints(self, stacked, optimizer, update: int, frames: int, finished: bool = False) -> None:
        for r, t in enumerate(self.trainers):
            t._checkpoint(stacked.unstack(r), optimizer_state(optimizer, r), update, frames, finished)

    def _loop(self, stacked: StackedModels, optimizer, update: int, frames: int) -> list[tuple[dict, int]]:
        cfg, device, n = self.cfg, self.device, len(self.trainers)
        B, T = cfg.num_envs, cfg.num_steps
        mask = torch.as_tensor(channel_mask(self.trainers[0].vocab, tuple(cfg.env.aux_words)), device=device)
        with Sampler(cfg, device, runs=n) as sampler:
            shapes = {k: (s.shape, _dtype(s)) for k, s in sampler.single_observation_space.spaces.items()}
            buffer = RolloutBuffer(T, B * n, shapes, device=device)
            # actor b of run r (actor b * n + r) gets the env seed its plain run gives its actor b
            seeds = [t.cfg.seed * 1000 + update * B + b for b in range(B) for t in self.trainers]
            sampler.reset(stacked, seed=seeds)
            next_eval = (frames // cfg.eval_every + 1) * cfg.eval_every if cfg.eval_every else None
            while update < cfg.num_updates:
                t_start = time.perf_counter()
                with conv_precision(stacked, cfg.precision):
                    sampler.collect(stacked, buffer)
                    buffer.compute_returns(sampler.last_value(stacked), cfg.ppo.gamma, cfg.ppo.gae_lambda)
                    stats = packed_ppo_update(stacked, optimizer, buffer, cfg.ppo, mask, use_aux=cfg.aux)
                update += 1
                frames += B * T
                fps = B * T * n / (time.perf_counter() - t_start)
                for r, t in enumerate(self.trainers):
                    recent = sampler.recent_by_run[r]
                    metrics = update_metrics(stats[r], fps / n, recent, update, sampler.dropped_episodes)
                    metrics["charts/packed_fps"] = fps
                    t.tracker.log_metrics(metrics, step=frames)
                if not self.quiet and update % cfg.log_every == 0:
                    line = " ".join(
                        f"s{t.cfg.seed} sgn {np.mean(sampler.recent_by_run[r][0] or [np.nan]):.2f}"
                        for r, t in enumerate(self.trainers)
                    )
                    print(f"update {update:>5} frames {frames:>9,} x {n} runs, {fps:6.0f} frames/s in all | {line}")
                if next_eval is not None and frames >= next_eval and update < cfg.num_updates:
                    for r, t in enumerate(self.trainers):
                        t._eval(stacked.unstack(r), frames)
                    next_eval += cfg.eval_every
                if update % cfg.checkpoint_every == 0 or update == cfg.num_updates:
                    self._checkpoints(stacked, optimizer, update, frames)
        finals = []
        for r, t in enumerate(self.trainers):
            final = t._eval(stacked.unstack(r), frames, final=True)
            t._write_results(final, frames)
            finals.append((final, frames))
        self._checkpoints(stacked, optimizer, update, frames, finished=True)
        return finals


def train_packed(cfgs: list[TrainConfig], quiet: bool = False) -> list[RunResult]:
    """Train (or resume, or skip the finished ones of) runs that differ only in seed, packed in this process."""
    return PackedTrainer([dataclasses.replace(c) for c in cfgs], quiet=quiet).train()
