"""The one trainer of every table: PPO + answer cross-entropy + auxiliary BCE (paper §3.3, Appendix A).

Loop: collect `num_steps` steps from `num_envs` actors (worker processes, uint8 shared-memory observations), then
`ppo_update` replays each actor's sequence from the stored GRU state with resets at episode starts. Metrics go to
MLflow every update under `losses/`, `charts/`, `train/`, `eval/`; a checkpoint (model, optimizer, RNG states,
counters, vocabulary, config, MLflow run id) is written atomically every `checkpoint_every` updates. Rerunning
the same config resumes from it in the same MLflow run; a finished run is not retrained.
"""

from __future__ import annotations

import logging
import random
import sys
import time
from datetime import datetime, timezone

import numpy as np
import torch
from tqdm import tqdm

from emml.config.schema import TrainConfig
from emml.envs.engine import stop_after
from emml.envs.labels import channel_mask
from emml.eval.diagnose import SCALARS, diagnose, saturation_warning, summary_line
from emml.eval.diagnose_gate import gate_metrics
from emml.eval.evaluate import evaluate
from emml.models import build_model
from emml.models.compiled import compile_model, wants_compile
from emml.rl import alloc
from emml.rl.contention import retake_cores, take_cores
from emml.rl.graphs import Graphs, Kept, captures, mean_stats
from emml.rl.ppo import explained_variance, make_optimizer, model_forward, ppo_step, ppo_update
from emml.rl.precision import conv_precision
from emml.rl.prepare import prepare
from emml.rl.progress import TIME_SPLIT, eta_text, log_line, say, success_text, update_metrics
from emml.rl.rollout import RolloutBuffer
from emml.rl.sampler import Sampler
from emml.runs.checkpoint import load_checkpoint, rng_state, save_checkpoint, set_rng_state
from emml.runs.mirror import read_mirror
from emml.runs.preflight import ensure_store
from emml.runs.records import cut_torn_tail, read_points
from emml.runs.rundir import (
    CHECKPOINT,
    EVAL_SEED,
    FINAL,
    METRICS,
    RESULTS,
    RunResult,
    check_resumable,
    git_sha,
    path_of,
    read_results,
    record_result,
    results_payload,
    run_name,
    run_tags,
    save_results,
    score_tags,
    utc_ms,
)
from emml.runs.runlock import hold_run
from emml.runs.segments import begin_segment
from emml.runs.tracking import Tracker, display_name
from emml.tasks.language import load_dataset, resolve_vocabulary

log = logging.getLogger(__name__)


def _seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


class Trainer:
    def __init__(
        self, cfg: TrainConfig, tracker: Tracker | None = None, quiet: bool = False, parent_run_id: str | None = None
    ):
        (self.cfg,) = prepare(cfg, writes=False)  # values, registry, machine: before compute (its writes: its caller's)
        self.parent_run_id = parent_run_id
        self.name = run_name(cfg)
        self.dir = path_of(cfg.run_root, cfg.table, self.name)
        self.tracker = tracker or Tracker()
        self.quiet = quiet
        dataset = load_dataset(cfg.env.dataset)
        # the vocabulary is part of the run's config (pinned to its word list) and saved with checkpoints
        self.vocab = resolve_vocabulary(cfg.env.vocabulary, dataset)
        cfg.env.vocabulary = self.vocab.words
        if cfg.env.aux_words is None:
            from emml.envs.labels import default_aux_words

            cfg.env.aux_words = default_aux_words(self.vocab, dataset)
        self.device = torch.device(cfg.device)
        self.git_sha = git_sha()  # the code this process runs: read once, before the tree can change under it
        self.started_at: str | None = None
        """When the run first started (UTC ISO; its checkpoint's, kept on resume; None for a checkpoint from before)."""
        self.consistent: tuple[int, int] | None = None
        """(update, frames) of the last whole update while the model and optimizer are that update's; None while an
        update steps them (`train_loop` sets it), so that a stop keeps only a whole update (`checkpoint_on_stop`)."""
        self.saved_update = -1
        """The update of the last checkpoint this process saved (-1: none yet)."""

    # --- public ---------------------------------------------------------------------------------------------
    def train(self) -> RunResult:
        with hold_run(self.dir):  # one process per run (RunLocked before anything is read or written)
            return self._train()

    def _train(self) -> RunResult:
        opened = self.open()
        if isinstance(opened, RunResult):
            return opened
        model, optimizer, update, frames, resumed = opened
        self.consistent = (update, frames)
        try:
            metrics = self._loop(model, optimizer, update, frames)
        except BaseException as e:  # KILLED on Ctrl-C, SIGTERM/SIGHUP (install_signal_handlers), else FAILED
            if isinstance(e, (KeyboardInterrupt, SystemExit)):
                self.checkpoint_on_stop(model, optimizer)
            self.tracker.abort(e)
            raise
        self.tracker.finish("FINISHED")
        return RunResult(self.dir, self.tracker.run_id, metrics.pop("_frames"), metrics, resumed=resumed)

    def saved(self) -> dict | None:
        """This run's checkpoint, checked against the config (ConfigMismatch names the fields), or None."""
        path = self.dir / CHECKPOINT
        if not path.exists():
            return None
        saved = load_checkpoint(path)
        check_resumable(saved["config"], self.cfg, path)
        return saved

    def finished(self, saved: dict | None = None) -> bool:
        """Whether this run's checkpoint (``saved``, else read) holds the whole run: nothing left to train."""
        saved = saved if saved is not None else self.saved()
        return bool(
            saved and saved.get("finished") and saved["frames"] >= self.cfg.num_updates * self.cfg.frames_per_update
        )

    def open(self, build: bool = True):
        """Everything before the loop: the checkpoint read and checked, the model and optimizer built (and
        restored), the MLflow run started. Returns the RunResult of a finished run (nothing to train), else
        (model, optimizer, update, frames, resumed). With ``build=False`` (packed runs, emml/rl/packed_trainer.py)
        the model is built from this run's seed but not compiled, and the optimizer's state is returned raw."""
        cfg = self.cfg
        saved = self.saved()
        if self.finished(saved):
            results = read_results(self.dir / RESULTS)  # RunDirError names the file and the line
            record_result(results, self.cfg)  # (re)record it: the results table may be a fresh checkout
            return RunResult(self.dir, saved["run_id"], saved["frames"], results["metrics"], skipped=True)
        alloc.tune_glibc()  # PPO reuses its large buffers from the heap (no-op under tcmalloc): docs/throughput.md
        warning = take_cores(cfg.threads)
        if warning:
            log.warning(warning)
        _seed_everything(cfg.seed)
        env_cfg = cfg.env
        model = build_model(
            cfg.model, len(self.vocab), env_cfg.height, env_cfg.width, env_cfg.max_steps, **cfg.model_options
        ).to(self.device)
        model.read_words(self.vocab.words, load_dataset(env_cfg.dataset).content_words())
        if cfg.cuda_graphs:
            model.capturable()
        optimizer = make_optimizer(model.parameters(), cfg.ppo, captures(cfg)) if build else None
        update, frames = 0, 0
        if saved is not None:
            model.load_state_dict(saved["model"])
            if optimizer is not None:
                optimizer.load_state_dict(saved["optimizer"])
            else:
                optimizer = saved["optimizer"]
            set_rng_state(saved["rng"])
            update, frames = saved["update"], saved["frames"]
        self.started_at = saved.get("started_at") if saved is not None else utc_now()
        if build and wants_compile(cfg.compile, self.device):
            compile_model(model)
        tags = run_tags(cfg, self.git_sha, alloc.loaded())
        # a kill mid-write leaves a torn last line: cut back first, or the resumed run's first point lands on it and
        # both are lost (issue 54); any other line that is no point fails naming it, before the MLflow run starts
        cut_torn_tail(self.dir / METRICS)
        read_points(self.dir / METRICS)
        self.tracker.mirror_to(self.dir / METRICS)
        if saved is not None and not (self.dir / METRICS).exists() and self.tracker.has_run(saved["run_id"]):
            self.tracker.export_to_mirror(saved["run_id"])  # a run dir from before the mirror existed
        if saved is not None:
            self.tracker.resume_after(frames)  # before start: a replay into a new store reads the mirror
        ensure_store(getattr(self.tracker, "_uri", None))  # a new store: its tables made once, under a lock
        run_id = self.tracker.start(
            cfg.table,
            display_name(self.dir, self.name),
            tags,
            cfg.to_dict(),
            run_id=saved["run_id"] if saved else None,
            parent_run_id=self.parent_run_id,
            start_time=utc_ms(self.started_at) if self.started_at else None,  # a run dir resumed in another store
        )
        if not self.quiet:  # what it starts, before minutes of it (a bare `emml train` trains 1.5M frames)
            total = cfg.num_updates * cfg.frames_per_update
            if saved is not None:
                say(f"resuming {self.name} from frame {frames:,} (update {update}) to {total:,}, MLflow run {run_id}")
            else:
                say(f"training {self.name}: {total:,} frames ({cfg.profile} profile, {cfg.device}) in {self.dir}")
        if saved is None:  # at once, so that a run killed before its first update resumes this MLflow run, not a second
            try:
                first = optimizer or make_optimizer(model.parameters(), cfg.ppo, captures(cfg))
                self.checkpoint(model, first, update, frames, False)
            except BaseException as e:  # a full disk, a run dir gone read-only: the run ends FAILED, not RUNNING
                self.tracker.abort(e)
                raise
        begin_segment(self.dir, self.git_sha, frames)  # this session's commit and first frame (issue 60)
        return model, optimizer, update, frames, saved is not None

    # --- the loop ---------------------------------------------------------------------------------------------
    def _loop(self, model, optimizer, update: int, frames: int) -> dict:
        return train_loop([self], PlainLearner(model, optimizer, self.cfg), update, frames)[0]

    # --- pieces -----------------------------------------------------------------------------------------------
    def eval_missed(self, frames: int) -> bool:
        """Whether the evaluation due at ``frames`` (the update that crossed an `eval_every` boundary) is missing from
        the run's curve: a stop during that evaluation keeps the update (`checkpoint_on_stop`) but not its point, and
        a run resumed there evaluates first."""
        every = self.cfg.eval_every
        if not every or frames == 0 or frames % every >= self.cfg.frames_per_update:
            return False
        return not any(step == frames and key.startswith("eval/") for step, key, _ in read_mirror(self.dir / METRICS))

    def evaluate_at(self, model, frames: int, final: bool = False) -> dict:
        """Greedy accuracies (logged under eval/): over `final_eval_episodes` per (task, split) for the run's score
        (``final``), `eval_episodes` for the curves."""
        t_start = time.perf_counter()
        episodes = self.cfg.final_eval_episodes if final else self.cfg.eval_episodes
        acc = evaluate(model, self.cfg.env, episodes, seed=EVAL_SEED, device=self.device)
        metrics = {f"eval/{k}": v for k, v in acc.items()}
        if final:  # the score, apart from the periodic evaluations' curve (whose last point it also is)
            metrics.update({f"{FINAL}{k}": v for k, v in acc.items()})
        if self.cfg.diagnose_episodes and self.cfg.env.tasks != "eqa":
            n = self.cfg.diagnose_episodes
            diag = diagnose(model, self.cfg.env, n, step0_episodes=5 * n, device=self.device)
            metrics.update({f"diag/{k}": diag[k] for k in SCALARS if diag[k] is not None})
            if not self.quiet:
                tqdm.write(f"frames {frames:,} eval " + ", ".join(f"{k} {v:.2f}" for k, v in acc.items()))
                tqdm.write(summary_line(diag))
            warning = saturation_warning(diag)  # a collapsed conv (issue 48) is said even in a quiet run
            if warning:
                tqdm.write(f"{self.name} frames {frames:,}: {warning}")
        metrics.update(gate_metrics(model, self.cfg, self.device))  # the question gate (issue 82), no engine
        metrics["perf/eval_s"] = time.perf_counter() - t_start  # what an evaluation costs (emml campaign's estimate)
        self.tracker.log_metrics(metrics, step=frames)
        return acc

    def checkpoint_on_stop(self, model, optimizer) -> None:
        """A stopped run (Ctrl-C, SIGTERM) keeps the updates it finished since its last checkpoint: unless it stopped
        inside an update (model and optimizer half-stepped), its state is that of its last whole update."""
        at = self.consistent
        if at is not None and at[0] > self.saved_update:
            self.checkpoint(model, optimizer, *at, finished=False)

    def checkpoint(self, model, optimizer, update: int, frames: int, finished: bool) -> None:
        """``optimizer``: the optimizer, or its state_dict (a packed run's slice, emml/rl/packed.py)."""
        save_checkpoint(
            self.dir / CHECKPOINT,
            {
                "model": model.state_dict(),
                "optimizer": optimizer if isinstance(optimizer, dict) else optimizer.state_dict(),
                "rng": rng_state(),
                "update": update,
                "frames": frames,
                "vocabulary": list(self.vocab.words),
                "config": self.cfg.to_dict(),
                "run_id": self.tracker.run_id,
                "finished": finished,
                "started_at": self.started_at,
            },
        )
        self.saved_update = update

    def write_results(self, metrics: dict, frames: int) -> None:
        times = {"started_at": self.started_at, "ended_at": utc_now()} if self.started_at else {"ended_at": utc_now()}
        payload = results_payload(self.cfg, metrics, frames, self.git_sha, self.tracker.run_id, times)
        if getattr(metrics, "questions", None):  # EQA per question (emml.eval.evaluate.Scores, issue 81)
            payload["questions"] = metrics.questions
        save_results(self.dir, payload, self.cfg)
        self.tracker.set_tags(score_tags(payload))  # as an imported run has them (emml/runs/import_runs.py)


def utc_now() -> str:
    """Now, UTC, ISO 8601 to the second: a run's ``started_at`` and ``ended_at``."""
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


class PlainLearner:
    """The learner of one run: its model acts, `ppo_update` steps its optimizer (emml/rl/ppo.py). A packed run's
    learner (emml/rl/packed_trainer.py, `PackedLearner`) has the same interface over N runs."""

    def __init__(self, model, optimizer, cfg: TrainConfig):
        self.model, self.optimizer, self.cfg = model, optimizer, cfg
        self.graphs = Graphs(cfg.device) if cfg.cuda_graphs else None
        """The captured calls of acting and the update (`TrainConfig.cuda_graphs`, emml/rl/graphs.py), or None."""

    def update(self, buffer: RolloutBuffer, mask: torch.Tensor) -> list[dict]:
        """One PPO update on the rollout (Appendix A); its losses, one dict per run."""
        model, cfg, optimizer = self.model, self.cfg, self.optimizer
        forward, params = model_forward(model), list(model.parameters())
        if self.graphs is None:
            return [ppo_update(forward, optimizer, params, buffer, cfg.ppo, mask, use_aux=cfg.aux)]

        def step(state):  # the paper's single batch, one optimiser step: replayed once per epoch
            return ppo_step(forward, optimizer, params, buffer, state, cfg.ppo, mask, use_aux=cfg.aux)

        key = ("update", id(buffer), model.trace_key())
        outs = self.graphs.step(key, step, buffer.initial_state, cfg.ppo.epochs, Kept(params, optimizer))
        return [mean_stats(outs) | {"explained_variance": explained_variance(buffer.values, buffer.returns)}]

    def run_model(self, r: int):
        """Run r's model, to evaluate and save."""
        return self.model

    def at_frames(self, frames: int) -> None:
        """The frames trained, before each rollout (`EmmlModel.at_frames`)."""
        self.model.at_frames(frames)

    def optimizer_state(self, r: int):
        """Run r's optimizer (or its state_dict), to save."""
        return self.optimizer


def env_seeds(seeds: list[int], update: int, num_envs: int) -> list[int]:
    """The env seed of every actor when a run starts or resumes at ``update``: actor b of the run of seed s gets
    s·1000 + update·num_envs + b. Several runs' actors are interleaved (packed runs, emml/rl/packed.py): actor
    b·N + r is actor b of run r."""
    return [s * 1000 + update * num_envs + b for b in range(num_envs) for s in seeds]


def train_loop(trainers: list[Trainer], learner, update: int, frames: int) -> list[dict]:
    """The one training loop, of a run (`PlainLearner`) or of N packed runs (one learner, one sampler over every
    run's actors): collect `num_steps` steps per actor, one update, then each run's metrics, evaluations and
    checkpoints at its cadences; at the end each run's final evaluation, results and finished checkpoint. Returns
    each run's final metrics (with ``_frames``). A run's ``consistent`` says whether its model and optimizer are
    those of a whole update (`Trainer.checkpoint_on_stop`)."""
    cfg, device, n = trainers[0].cfg, trainers[0].device, len(trainers)
    B, T = cfg.num_envs, cfg.num_steps
    quiet = trainers[0].quiet
    mask = torch.as_tensor(channel_mask(trainers[0].vocab, tuple(cfg.env.aux_words)), device=device)
    model = learner.model
    with Sampler(cfg, device, runs=n, graphs=learner.graphs) as sampler:
        shapes = {k: (s.shape, _dtype(s)) for k, s in sampler.single_observation_space.spaces.items()}
        buffer = RolloutBuffer(T, B * n, shapes, device=device)
        sampler.reset(model, seed=env_seeds([t.cfg.seed for t in trainers], update, B))
        next_eval = (frames // cfg.eval_every + 1) * cfg.eval_every if cfg.eval_every else None
        if update < cfg.num_updates:  # resumed where a stop cut an evaluation short: that point first
            for r, t in enumerate(trainers):
                if t.eval_missed(frames):
                    t.evaluate_at(learner.run_model(r), frames)
        total = cfg.num_updates * cfg.frames_per_update
        # a progress bar on a terminal only: piped to a file its \r frames would fill the log (the lines stay)
        bar = tqdm(
            total=total,
            initial=frames,
            unit="frame",
            disable=quiet or not sys.stderr.isatty(),
            dynamic_ncols=True,
            smoothing=0.1,
        )
        tasks = cfg.env.played  # the tasks the run plays, as lines say them
        since_line = dict.fromkeys(TIME_SPLIT, 0.0)  # the log line's split: since the previous line
        log_mark = start_mark = (time.perf_counter(), frames)
        while update < cfg.num_updates:
            t_start = time.perf_counter()
            learner.at_frames(frames)  # a schedule over the frames trained (answer_gate_frames) resumes with them
            with conv_precision(model, cfg.precision):
                sampler.collect(model, buffer)
                t_learn = time.perf_counter()
                last_value = sampler.last_value(model)
                buffer.compute_returns(last_value, cfg.ppo.gamma, cfg.ppo.gae_lambda)
                # a SIGTERM here stops the run after this update and its point of the curve, which it then keeps
                with stop_after():
                    for t in trainers:
                        t.consistent = None  # the update changes the model and optimizer step by step
                    stats = learner.update(buffer, mask)
                    update += 1
                    frames += B * T
                    for t in trainers:
                        t.consistent = (update, frames)
                    now = time.perf_counter()
                    seconds = sampler.timing | {"learn": now - t_learn}
                    fps = B * T * n / (now - t_start)
                    logged = []
                    for r, t in enumerate(trainers):
                        metrics = update_metrics(
                            stats[r], fps / n, sampler.recent_by_run[r], update, sampler.dropped_episodes, seconds
                        )
                        if n > 1:
                            metrics["charts/packed_fps"] = fps
                        t.tracker.log_metrics(metrics, step=frames)
                        logged.append(metrics)
            for part, value in seconds.items():
                since_line[part] += value
            first = logged[0]
            bar.update(B * T)
            if not bar.disable:
                bar.set_postfix({task: success_text(first, task) for task in tasks})  # as the lines write them
            if update % cfg.log_every == 0 and not quiet:
                now, since = time.perf_counter(), log_mark
                log_mark = (now, frames)
                line_fps = (frames - since[1]) / max(now - since[0], 1e-9)  # since the last line, evaluations included
                eta = eta_text(total - frames, (frames - start_mark[1]) / max(now - start_mark[0], 1e-9))
                if n == 1:
                    say(log_line(update, frames, line_fps, first, since_line, tasks=tasks, eta=eta))
                else:
                    seeds = " ".join(
                        f"s{t.cfg.seed} sgn {np.mean(sampler.recent_by_run[r][0] or [np.nan]):.2f}"
                        for r, t in enumerate(trainers)
                    )
                    head = f"update {update:>5} frames {frames:>9,} x {n} runs, {fps:6.0f} frames/s all"
                    say(f"{head} | {seeds} | eta {eta}")
                since_line = dict.fromkeys(TIME_SPLIT, 0.0)
            if next_eval is not None and frames >= next_eval and update < cfg.num_updates:
                for r, t in enumerate(trainers):
                    t.evaluate_at(learner.run_model(r), frames)
                next_eval += cfg.eval_every
                changed = retake_cores(cfg.threads)
                if changed and not quiet:
                    say(changed)
            if update % cfg.checkpoint_every == 0 or update == cfg.num_updates:
                for r, t in enumerate(trainers):
                    t.checkpoint(learner.run_model(r), learner.optimizer_state(r), update, frames, finished=False)
        bar.close()
    finals = []
    for r, t in enumerate(trainers):
        run_model, state = learner.run_model(r), learner.optimizer_state(r)
        final = {}
        if cfg.score:  # a measurement run is not scored
            final = t.evaluate_at(run_model, frames, final=True)
            t.checkpoint(run_model, state, update, frames, finished=False)
            t.write_results(final, frames)
        t.checkpoint(run_model, state, update, frames, finished=True)
        finals.append({**final, "_frames": frames})
    return finals


def _dtype(space) -> torch.dtype:
    return {np.uint8: torch.uint8}.get(space.dtype.type, torch.int64)


def train(cfg: TrainConfig, quiet: bool = False, parent_run_id: str | None = None) -> RunResult:
    """Train (or resume, or skip if finished) one run; `parent_run_id` nests its MLflow run
    (emml/experiments/launch.py)."""
    return Trainer(cfg, quiet=quiet, parent_run_id=parent_run_id).train()
