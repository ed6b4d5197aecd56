"""The one trainer of every table: PPO + answer cross-entropy + auxiliary BCE (paper §3.3, Appendix A).

Loop: collect `num_steps` steps from `num_envs` actors (worker processes, uint8 shared-memory observations), then
`ppo_update` replays each actor's sequence from the stored GRU state with resets at episode starts. Metrics go to
MLflow every update under `losses/`, `charts/`, `train/`, `eval/`; a checkpoint (model, optimizer, RNG states,
counters, vocabulary, config, MLflow run id) is written atomically every `checkpoint_every` updates. Rerunning
the same config resumes from it in the same MLflow run; a finished run is not retrained.
"""

from __future__ import annotations

import json
import logging
import os
import random
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from emml import alloc
from emml.config import TrainConfig
from emml.diagnose import SCALARS, diagnose, summary_line
from emml.diskspace import no_space_names
from emml.envs.labels import channel_mask
from emml.evaluate import evaluate
from emml.models import build_model
from emml.results import upsert_result
from emml.rl.checkpoint import load_checkpoint, rng_state, save_checkpoint, set_rng_state
from emml.rl.compiled import compile_model, wants_compile
from emml.rl.contention import share_cores
from emml.rl.ppo import make_optimizer, model_forward, ppo_update
from emml.rl.precision import conv_precision
from emml.rl.rollout import RolloutBuffer
from emml.rl.sampler import Sampler
from emml.runlock import hold_run
from emml.tasks.language import load_dataset, resolve_vocabulary
from emml.tracking import Tracker, project_path, project_root

log = logging.getLogger(__name__)
CHECKPOINT = "checkpoint.pt"
METRICS = "metrics.csv"
"""Every metric point of the run (step,key,value), mirrored beside its checkpoint (emml.tracking.Tracker.mirror_to)."""
RESULTS = "results.json"
EVAL_SEED = 10_000
"""Episode seeds of every greedy evaluation of a run: EVAL_SEED, EVAL_SEED + 1, … (emml.evaluate), recorded as
``eval_seed`` beside the score."""


def git_sha() -> str:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=project_root(), capture_output=True, text=True, timeout=5
        )
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def run_dir(cfg: TrainConfig) -> Path:
    return project_path(cfg.run_root) / cfg.table / cfg.run_name()


@dataclass
class RunResult:
    run_dir: Path
    run_id: str
    frames: int
    metrics: dict
    resumed: bool = False
    skipped: bool = False


def _seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


class ConfigMismatch(ValueError):
    """A rerun whose config differs from the checkpoint's run (the message names the fields)."""


def _check_same_config(saved: dict, current: dict, path: Path) -> None:
    """A rerun resumes only the same experiment: differing fields fail by name before anything is touched."""
    ignore = {
        "frames",  # asking for more frames continues a run (finished or not) to the new target
        "eval_every",
        "eval_episodes",  # how a run is measured, not what it is: the evaluations' size
        "final_eval_episodes",
        "diagnose_episodes",
        "checkpoint_every",
        "log_every",
        "threads",
        "asynchronous",
        "env_groups",  # how the actors are stepped, not what they do
        "envs_per_worker",
        "acting_threads",
        "max_engine_restarts",
        "engine_restart_window",
        "device",
        "compile",
        "run_root",
        "results_root",
    }
    # a field added since the checkpoint was written reads as its default: the run it describes is unchanged
    defaults = TrainConfig().to_dict()
    diffs = []
    for key in sorted(set(saved) | set(current)):
        if key in ignore:
            continue
        a, b = saved.get(key, defaults.get(key)), current.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            diffs += [f"{key}.{k}" for k in sorted(set(a) | set(b)) if _norm(a.get(k)) != _norm(b.get(k))]
        elif _norm(a) != _norm(b):
            diffs.append(key)
    if diffs:
        raise ConfigMismatch(
            f"{path} holds a run with a different config ({', '.join(diffs)}); use another seed/table/run_root, "
            "or delete that run directory"
        )


def _norm(v):
    return list(v) if isinstance(v, tuple) else v


class Trainer:
    def __init__(
        self, cfg: TrainConfig, tracker: Tracker | None = None, quiet: bool = False, parent_run_id: str | None = None
    ):
        self.cfg = cfg.validate()
        self.parent_run_id = parent_run_id
        self.dir = run_dir(cfg)
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

    # --- public ---------------------------------------------------------------------------------------------
    def train(self) -> RunResult:
        with hold_run(self.dir):  # one process per run (RunLocked before anything is read or written)
            return self._train()

    def _train(self) -> RunResult:
        opened = self.open()
        if isinstance(opened, RunResult):
            return opened
        model, optimizer, update, frames, resumed = opened
        self._consistent = (update, frames)
        try:
            metrics = self._loop(model, optimizer, update, frames)
        except BaseException as e:  # KILLED on Ctrl-C, SIGTERM/SIGHUP (install_signal_handlers), else FAILED
            if isinstance(e, (KeyboardInterrupt, SystemExit)):
                self._checkpoint_on_stop(model, optimizer)
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
        _check_same_config(saved["config"], self.cfg.to_dict(), path)
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
            results = json.loads((self.dir / RESULTS).read_text())
            record_result(results, self.cfg)  # (re)record it: the results table may be a fresh checkout
            return RunResult(self.dir, saved["run_id"], saved["frames"], results["metrics"], skipped=True)
        alloc.tune_glibc()  # PPO reuses its large buffers from the heap (no-op under tcmalloc): docs/throughput.md
        threads, warning = share_cores(cfg.threads)
        if warning:
            log.warning(warning)
        if threads:
            torch.set_num_threads(threads)
        _seed_everything(cfg.seed)
        env_cfg = cfg.env
        model = build_model(
            cfg.model, len(self.vocab), env_cfg.height, env_cfg.width, env_cfg.max_steps, **cfg.model_options
        ).to(self.device)
        optimizer = make_optimizer(model.parameters(), cfg.ppo) if build else None
        update, frames = 0, 0
        if saved is not None:
            model.load_state_dict(saved["model"])
            if optimizer is not None:
                optimizer.load_state_dict(saved["optimizer"])
            else:
                optimizer = saved["optimizer"]
            set_rng_state(saved["rng"])
            update, frames = saved["update"], saved["frames"]
        if build and wants_compile(cfg.compile, self.device):
            compile_model(model)
        tags = {
            "table": cfg.table,
            "model": cfg.model,
            "difficulty": env_cfg.difficulty,
            "aux": cfg.aux,
            "seed": cfg.seed,
            "profile": cfg.profile,
            "git_sha": self.git_sha,
            "allocator": alloc.loaded(),
            "tasks": env_cfg.tasks,
            "shaping": env_cfg.shaping,
            "precision": cfg.precision,
            "checkpoint": str(self.dir / CHECKPOINT),
        }
        self.tracker.mirror_to(self.dir / METRICS)
        if saved is not None and not (self.dir / METRICS).exists() and self.tracker.has_run(saved["run_id"]):
            self.tracker.export_to_mirror(saved["run_id"])  # a run dir from before the mirror existed
        if saved is not None:
            self.tracker.resume_after(frames)  # before start: a replay into a new store reads the mirror
        run_id = self.tracker.start(
            cfg.table,
            cfg.run_name(),
            tags,
            cfg.to_dict(),
            run_id=saved["run_id"] if saved else None,
            parent_run_id=self.parent_run_id,
        )
        if saved is not None:
            if not self.quiet:
                tqdm.write(f"resuming {cfg.run_name()} from frame {frames:,} (update {update}), MLflow run {run_id}")
        else:  # at once, so that a run killed before its first update resumes this MLflow run, not a second one
            try:
                self._checkpoint(model, optimizer or make_optimizer(model.parameters(), cfg.ppo), update, frames, False)
            except BaseException as e:  # a full disk, a run dir gone read-only: the run ends FAILED, not RUNNING
                self.tracker.abort(e)
                raise
        return model, optimizer, update, frames, saved is not None

    # --- the loop ---------------------------------------------------------------------------------------------
    def _loop(self, model, optimizer, update: int, frames: int) -> dict:
        cfg, device = self.cfg, self.device
        B, T = cfg.num_envs, cfg.num_steps
        mask = torch.as_tensor(channel_mask(self.vocab, tuple(cfg.env.aux_words)), device=device)
        with Sampler(cfg, device) as sampler:
            shapes = {k: (s.shape, _dtype(s)) for k, s in sampler.single_observation_space.spaces.items()}
            buffer = RolloutBuffer(T, B, shapes, device=device)
            sampler.reset(model, seed=cfg.seed * 1000 + update * B)
            recent = sampler.recent
            next_eval = (frames // cfg.eval_every + 1) * cfg.eval_every if cfg.eval_every else None
            bar = tqdm(
                total=cfg.num_updates * cfg.frames_per_update,
                initial=frames,
                unit="frame",
                disable=self.quiet,
                dynamic_ncols=True,
                smoothing=0.1,
            )
            since_line = dict.fromkeys(TIME_SPLIT, 0.0)  # the log line's split: since the previous line
            log_mark = (time.perf_counter(), frames)
            while update < cfg.num_updates:
                t_start = time.perf_counter()
                with conv_precision(model, cfg.precision):
                    sampler.collect(model, buffer)
                    t_learn = time.perf_counter()
                    last_value = sampler.last_value(model)
                    buffer.compute_returns(last_value, cfg.ppo.gamma, cfg.ppo.gae_lambda)
                    self._consistent = None  # the update changes the model and optimizer step by step
                    stats = ppo_update(
                        model_forward(model), optimizer, model.parameters(), buffer, cfg.ppo, mask, use_aux=cfg.aux
                    )
                update += 1
                frames += B * T
                self._consistent = (update, frames)
                now = time.perf_counter()
                seconds = sampler.timing | {"learn": now - t_learn}
                for part, value in seconds.items():
                    since_line[part] += value
                metrics = update_metrics(
                    stats, B * T / (now - t_start), recent, update, sampler.dropped_episodes, seconds
                )
                self.tracker.log_metrics(metrics, step=frames)
                bar.update(B * T)
                bar.set_postfix(
                    sgn=f"{metrics.get('train/success_sgn', 0):.2f}", eqa=f"{metrics.get('train/success_eqa', 0):.2f}"
                )
                if update % cfg.log_every == 0 and not self.quiet:
                    now, since = time.perf_counter(), log_mark
                    log_mark = (now, frames)
                    fps = (frames - since[1]) / max(now - since[0], 1e-9)  # since the last line, evaluations included
                    bar.write(_log_line(update, frames, fps, metrics, since_line))
                    since_line = dict.fromkeys(TIME_SPLIT, 0.0)
                if next_eval is not None and frames >= next_eval and update < cfg.num_updates:
                    self._eval(model, frames)
                    next_eval += cfg.eval_every
                if update % cfg.checkpoint_every == 0 or update == cfg.num_updates:
                    self._checkpoint(model, optimizer, update, frames, finished=False)
            bar.close()
        final = self._eval(model, frames, final=True)
        self._checkpoint(model, optimizer, update, frames, finished=False)
        self._write_results(final, frames)
        self._checkpoint(model, optimizer, update, frames, finished=True)
        final["_frames"] = frames
        return final

    # --- pieces -----------------------------------------------------------------------------------------------
    def _eval(self, model, frames: int, final: bool = False) -> dict:
        """Greedy accuracies (logged under eval/): over `final_eval_episodes` per (task, split) for the run's score
        (``final``), `eval_episodes` for the curves."""
        t_start = time.perf_counter()
        episodes = self.cfg.final_eval_episodes if final else self.cfg.eval_episodes
        acc = evaluate(model, self.cfg.env, episodes, seed=EVAL_SEED, device=self.device)
        metrics = {f"eval/{k}": v for k, v in acc.items()}
        if self.cfg.diagnose_episodes and self.cfg.env.tasks != "eqa":
            n = self.cfg.diagnose_episodes
            diag = diagnose(model, self.cfg.env, n, step0_episodes=5 * n, device=self.device)
            metrics.update({f"diag/{k}": diag[k] for k in SCALARS if diag[k] is not None})
            if not self.quiet:
                tqdm.write(f"frames {frames:,} eval " + ", ".join(f"{k} {v:.2f}" for k, v in acc.items()))
                tqdm.write(summary_line(diag))
        metrics["perf/eval_s"] = time.perf_counter() - t_start  # what an evaluation costs (emml campaign's estimate)
        self.tracker.log_metrics(metrics, step=frames)
        return acc

    def _checkpoint_on_stop(self, model, optimizer) -> None:
        """A stopped run (Ctrl-C, SIGTERM) keeps the updates it finished since its last checkpoint: unless it stopped
        inside an update (model and optimizer half-stepped), its state is that of its last whole update."""
        at = getattr(self, "_consistent", None)
        if at is not None and at[0] > getattr(self, "_saved_update", -1):
            self._checkpoint(model, optimizer, *at, finished=False)

    def _checkpoint(self, model, optimizer, update: int, frames: int, finished: bool) -> None:
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
            },
        )
        self._saved_update = update

    def _write_results(self, metrics: dict, frames: int) -> None:
        cfg = self.cfg
        payload = {
            **run_identity(cfg),
            "frames": frames,
            "git_sha": self.git_sha,
            "run_id": self.tracker.run_id,
            "eval_episodes": cfg.final_eval_episodes,  # the score's: the final evaluation's
            "eval_seed": EVAL_SEED,
            "metrics": metrics,
            "config": cfg.to_dict(),  # what the run trained with: reports state its deviations from the paper
        }
        save_results(self.dir, payload, cfg)


def run_identity(cfg: TrainConfig) -> dict:
    """What names a run in its results.json and results row (its provenance follows: frames, git sha, run id)."""
    return {
        "run_name": cfg.run_name(),
        "table": cfg.table,
        "model": cfg.model,
        "difficulty": cfg.env.difficulty,
        "aux": cfg.aux,
        "seed": cfg.seed,
        "profile": cfg.profile,
    }


def save_results(directory: Path, payload: dict, cfg: TrainConfig, record: bool = True) -> None:
    """Write a run's results.json atomically, then (``record``) upsert its row in the results CSV (`record_result`)."""
    tmp = directory / (RESULTS + ".tmp")
    with no_space_names(directory / RESULTS, tmp):
        tmp.write_text(json.dumps(payload, indent=2))
        os.replace(tmp, directory / RESULTS)
    if record:
        record_result(payload, cfg)


def results_csv(cfg: TrainConfig) -> Path:
    return project_path(cfg.results_root) / cfg.table / f"{cfg.profile}.csv"


def record_result(payload: dict, cfg: TrainConfig) -> Path:
    """Upsert the run's row (keyed by run name) in results/<table>/<profile>.csv (emml.results)."""
    from emml.profiles import refuse_committed

    refuse_committed(cfg.profile, results_csv(cfg), "results CSV")  # smoke numbers are not results
    row = {k: v for k, v in payload.items() if k not in ("metrics", "config")}
    row.update(tasks=cfg.env.tasks, shaping=cfg.env.shaping, precision=cfg.precision, **payload["metrics"])
    return upsert_result(results_csv(cfg), row)


def update_metrics(
    stats: dict, fps: float, recent: dict, update: int, dropped: int, seconds: dict | None = None
) -> dict:
    """What a run logs after each update: its losses, frames/s, training success per task (last 100 episodes),
    the update count, the episodes dropped to engine deaths, and the update's seconds waiting on the envs, acting
    and learning (``perf/simulate_s``, ``perf/infer_s``, ``perf/learn_s``)."""
    metrics = {f"losses/{k}": v for k, v in stats.items()}
    metrics["charts/fps"] = fps
    for task_id, name in ((0, "sgn"), (1, "eqa")):
        if recent[task_id]:
            metrics[f"train/success_{name}"] = float(np.mean(recent[task_id]))
    metrics["charts/update"] = update
    metrics["charts/dropped_episodes"] = dropped
    for part, value in (seconds or {}).items():
        metrics[f"perf/{part}_s"] = value
    return metrics


TIME_SPLIT = ("simulate", "infer", "learn")
"""Where an update's time goes: waiting on the envs, acting, learning (the metrics ``perf/<part>_s``)."""


def time_shares(seconds: dict[str, float]) -> dict[str, float]:
    """Each part's share of the seconds given."""
    total = sum(seconds.values()) or 1.0
    return {part: v / total for part, v in seconds.items()}


def _dtype(space) -> torch.dtype:
    return {np.uint8: torch.uint8}.get(space.dtype.type, torch.int64)


def _log_line(update: int, frames: int, fps: float, m: dict, seconds: dict) -> str:
    split = "/".join(f"{100 * share:.0f}" for share in time_shares(seconds).values())
    return (
        f"update {update:>5} frames {frames:>9,} fps {fps:6.0f} "
        f"sgn {m.get('train/success_sgn', float('nan')):.2f} eqa {m.get('train/success_eqa', float('nan')):.2f} "
        f"pg {m['losses/policy']:+.3f} v {m['losses/value']:.3f} ent {m['losses/entropy']:.3f} "
        f"ans {m['losses/answer']:.3f}"
        + (f" aux {m['losses/aux']:.3f}" if "losses/aux" in m else "")
        + (f" dropped {m['charts/dropped_episodes']}" if m.get("charts/dropped_episodes") else "")
        + f" | sim/infer/learn % {split}"
    )


def train(cfg: TrainConfig, quiet: bool = False, parent_run_id: str | None = None) -> RunResult:
    """Train (or resume, or skip if finished) one run; `parent_run_id` nests its MLflow run (emml/launch.py)."""
    return Trainer(cfg, quiet=quiet, parent_run_id=parent_run_id).train()
