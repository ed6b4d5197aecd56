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
from contextlib import ExitStack

from emml.config.schema import TrainConfig
from emml.rl.graphs import Graphs, Kept, captures, mean_stats
from emml.rl.packed import (
    StackedModels,
    load_optimizer_state,
    optimizer_state,
    packed_ppo_step,
    packed_ppo_update,
    run_explained_variance,
)
from emml.rl.ppo import make_optimizer
from emml.rl.trainer import Trainer, train_loop
from emml.runs.rundir import RunResult
from emml.runs.runlock import hold_run
from emml.runs.tracking import Tracker

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
        learner = None
        try:  # from the first MLflow run started (open), a failure ends every started run, never leaves it RUNNING
            opened = [t.open(build=False) for t in self.trainers]
            stacked = StackedModels([o[0] for o in opened]).to(self.device)
            if self.cfg.cuda_graphs:
                stacked.capturable()
            optimizer = make_optimizer(stacked.parameters_in_order(), self.cfg.ppo, captures(self.cfg))
            for r, o in enumerate(opened):
                if o[1] is not None:
                    load_optimizer_state(optimizer, r, o[1])
            update, frames = opened[0][2], opened[0][3]
            learner = PackedLearner(stacked, optimizer, self.cfg)
            for t in self.trainers:
                t.consistent = (update, frames)
            finals = [(m, m.pop("_frames")) for m in train_loop(self.trainers, learner, update, frames)]
        except BaseException as e:  # KILLED on Ctrl-C or a termination signal, else FAILED (Tracker.abort)
            if learner is not None and isinstance(e, (KeyboardInterrupt, SystemExit)):
                for r, t in enumerate(self.trainers):  # each run keeps its last whole update, as a plain run does
                    t.checkpoint_on_stop(learner.run_model(r), learner.optimizer_state(r))
            for t in self.trainers:
                t.tracker.abort(e)
            raise
        results = []
        for t, (metrics, frames), o in zip(self.trainers, finals, opened):
            t.tracker.finish("FINISHED")
            results.append(RunResult(t.dir, t.tracker.run_id, frames, metrics, resumed=o[4]))
        return results


class PackedLearner:
    """The learner of N packed runs: the stacked model acts for every run's actors, `packed_ppo_update` steps each
    run's parameters by its own PPO update (emml/rl/packed.py); run r's model and optimizer state come back as a
    plain run's, for its evaluations and checkpoints."""

    def __init__(self, stacked: StackedModels, optimizer, cfg: TrainConfig):
        self.model, self.optimizer, self.cfg = stacked, optimizer, cfg
        self.graphs = Graphs(cfg.device) if cfg.cuda_graphs else None
        """The captured calls of acting and the update (`TrainConfig.cuda_graphs`, emml/rl/graphs.py), or None."""

    def update(self, buffer, mask) -> list[dict]:
        """Every run's PPO update on its actors' rollout; their losses, one dict per run."""
        stacked, optimizer, cfg = self.model, self.optimizer, self.cfg
        if self.graphs is None:
            return packed_ppo_update(stacked, optimizer, buffer, cfg.ppo, mask, use_aux=cfg.aux)

        def step(state):  # every run's optimiser step on the whole rollout: replayed once per epoch
            return packed_ppo_step(stacked, optimizer, buffer, state, cfg.ppo, mask, use_aux=cfg.aux)

        key = ("update", id(buffer), stacked.trace_key())
        kept = Kept(stacked.parameters_in_order(), optimizer)
        outs = self.graphs.step(key, step, buffer.initial_state, cfg.ppo.epochs, kept)
        n = stacked.runs
        return [
            mean_stats([o[r] for o in outs]) | {"explained_variance": run_explained_variance(buffer, n, r)}
            for r in range(n)
        ]

    def run_model(self, r: int):
        return self.model.unstack(r)

    def at_frames(self, frames: int) -> None:
        """The frames trained (the same for every packed run), told to the module each run's forward calls."""
        self.model.template[0].at_frames(frames)

    def optimizer_state(self, r: int) -> dict:
        return optimizer_state(self.optimizer, r)


def train_packed(cfgs: list[TrainConfig], quiet: bool = False) -> list[RunResult]:
    """Train (or resume, or skip the finished ones of) runs that differ only in seed, packed in this process."""
    return PackedTrainer([dataclasses.replace(c) for c in cfgs], quiet=quiet).train()
