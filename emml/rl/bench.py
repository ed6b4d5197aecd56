"""`emml bench env`: throughput of our env against the raw engine it wraps, measured in one run.

Raw: the same DoomGame (same map and objects, resolution, buffers, tics per step) stepped with `make_action` +
`get_state`.
Ours: `DoomEnv.step` (action mapping, resize, labels, rewards, observation dict). Both with random moves; reset
time is measured apart (ours: sampling a scene, placing 5 objects; raw: `new_episode`). Then the vector env with
1 and 2 worker processes, resets included.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from emml.config.env_kinds import GYM_ENVS
from emml.config.schema import DoomConfig
from emml.envs.doom import DoomEnv
from emml.envs.vector import make_env, make_vector_env


def _raw(env: DoomEnv, steps: int, rng) -> tuple[float, float]:
    env.reset(seed=0)  # the same room with the same 5 objects; raw steps never end the episode
    game = env._game()
    turn = env._turn
    choices = [[1, 0], [0, -turn], [0, turn], [0, 0]]
    t0 = time.perf_counter()
    for _ in range(steps):
        game.make_action(choices[rng.integers(4)], env.cfg.frame_skip)
        game.get_state()
    step_time = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(20):
        game.new_episode()
        game.get_state()
    return steps / step_time, (time.perf_counter() - t0) / 20


def _ours(env: DoomEnv, steps: int, rng) -> tuple[float, float]:
    env.reset(seed=0)
    step_time, reset_time, resets, done = 0.0, 0.0, 0, 0
    while done < steps:
        action = np.array([rng.integers(3), 0])  # moves only: answers would end EQA episodes at once
        t0 = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(action)
        step_time += time.perf_counter() - t0
        done += 1
        if terminated or truncated:
            t0 = time.perf_counter()
            env.reset()
            reset_time += time.perf_counter() - t0
            resets += 1
    for _ in range(20):  # enough resets for a stable figure
        t0 = time.perf_counter()
        env.reset()
        reset_time += time.perf_counter() - t0
        resets += 1
    return steps / step_time, reset_time / resets


def _vector(config: DoomConfig, workers: int, steps: int) -> float:
    with make_vector_env(config, workers) as venv:
        venv.reset(seed=0)
        rng = np.random.default_rng(0)
        t0 = time.perf_counter()
        for _ in range(steps // workers):
            venv.step(np.stack([rng.integers(3, size=workers), np.zeros(workers, dtype=np.int64)], axis=1))
        return (steps // workers) * workers / (time.perf_counter() - t0)


def bench_env(config: DoomConfig, steps: int = 2000, vector_steps: int = 2000) -> dict:
    """Steps/s of raw engine vs our env (labels off and on), and of the vector env with 1 and 2 workers. A
    HouseConfig measures the House env (Appendix C) the same way."""
    rng = np.random.default_rng(0)
    out: dict = {"height": config.height, "width": config.width, "render": "x".join(map(str, config.render_size()))}
    out["env"] = GYM_ENVS[config.GYM_ID].name
    for aux in (False, True):
        cfg = type(config)(**{**config.to_dict(), "aux_labels": aux})
        env = make_env(cfg)
        try:
            raw_sps, raw_reset = _raw(env, steps, rng)
            ours_sps, ours_reset = _ours(env, steps, rng)
        finally:
            env.close()
        key = "labels_on" if aux else "labels_off"
        out[key] = {
            "raw_steps_per_s": round(raw_sps, 1),
            "env_steps_per_s": round(ours_sps, 1),
            "ratio": round(ours_sps / raw_sps, 3),
            "raw_new_episode_ms": round(raw_reset * 1000, 2),
            "env_reset_ms": round(ours_reset * 1000, 2),
        }
    for workers in (1, 2):
        out[f"vector_{workers}_workers_steps_per_s"] = round(_vector(config, workers, vector_steps), 1)
    return out


# --- `emml bench train` ---------------------------------------------------------------------------------------


class MemoryTracker:
    """Stands in for tracking.Tracker in benchmarks: keeps metrics in memory, writes nothing."""

    def __init__(self):
        self.run_id = "bench"
        self.history: list[tuple[int, dict]] = []

    def start(self, *args, **kwargs) -> str:
        return self.run_id

    def log_metrics(self, metrics: dict, step: int) -> None:
        self.history.append((step, dict(metrics)))

    def finish(self, status: str = "FINISHED") -> None:
        pass

    def abort(self, exc: BaseException) -> None:  # the trainer's error propagates; nothing is stored to end
        pass

    def mirror_to(self, path) -> None:  # the run dir's metrics.csv: a benchmark keeps nothing
        pass

    def resume_after(self, step: int) -> None:
        pass

    def has_run(self, run_id: str) -> bool:
        return True

    def export_to_mirror(self, run_id: str) -> int:
        return 0


SYNTHETIC_EPISODE = 32
"""Steps per episode in model-only's synthetic rollout, over which an actor's instruction stays the same (the text
encoder encodes each distinct instruction of the update once)."""


def _model_only(cfg, updates: int, stack: int = 1) -> float:
    """Frames/s of acting (T batched forward steps) + one PPO update on synthetic observations of the real shapes;
    with ``stack`` N > 1, of N runs stacked in one model (emml/rl/packed.py), all their frames counted."""
    import torch

    from emml.config.geometry import conv_output_size
    from emml.envs.labels import channel_mask, default_aux_words
    from emml.models import build_model
    from emml.models.compiled import compile_model, wants_compile
    from emml.rl.graphs import acting, captures
    from emml.rl.packed import StackedModels
    from emml.rl.packed_trainer import PackedLearner
    from emml.rl.ppo import make_optimizer
    from emml.rl.precision import conv_precision
    from emml.rl.rollout import RolloutBuffer
    from emml.rl.trainer import PlainLearner
    from emml.tasks.language import Vocabulary, load_dataset

    env, device = cfg.env, torch.device(cfg.device)
    dataset = load_dataset(env.dataset)
    vocab = Vocabulary.from_dataset(dataset)
    V, (h, w), T = len(vocab), conv_output_size(env.height, env.width), cfg.num_steps
    B = cfg.num_envs * stack
    models = [  # the run's model: its options (`--set model_options.…`) included
        build_model(cfg.model, V, env.height, env.width, env.max_steps, **cfg.model_options).read_words(
            vocab.words, dataset.content_words()
        )
        for _ in range(stack)
    ]
    model = (StackedModels(models) if stack > 1 else models[0]).to(device)
    if wants_compile(cfg.compile, device) and stack == 1:
        compile_model(model)
    if cfg.cuda_graphs:
        model.capturable()
    params = model.parameters_in_order() if stack > 1 else list(model.parameters())
    optimizer = make_optimizer(params, cfg.ppo, captures(cfg))
    learner = (PackedLearner if stack > 1 else PlainLearner)(model, optimizer, cfg)  # the trainer's update
    shapes = {
        "image": ((3, env.height, env.width), torch.uint8),
        "tokens": ((env.max_words,), torch.int64),
        "task": ((), torch.int64),
        "time": ((), torch.int64),
    }
    if cfg.aux:
        shapes["aux"] = ((V, h, w), torch.uint8)
    buffer = RolloutBuffer(T, B, shapes, device=device)
    gen = torch.Generator().manual_seed(0)
    for key, tensor in buffer.obs.items():
        high = {"image": 256, "tokens": V + 1, "task": 2, "time": env.max_steps, "aux": 2}[key]
        tensor.copy_(torch.randint(0, high, tensor.shape, generator=gen))
    # one instruction per actor and episode, as in a rollout (episodes of SYNTHETIC_EPISODE steps)
    episode = torch.arange(T) // SYNTHETIC_EPISODE
    buffer.obs["tokens"].copy_(buffer.obs["tokens"][episode])  # indexing by a tensor copies: no aliasing
    buffer.rewards.copy_(torch.randn(buffer.rewards.shape, generator=gen))
    mask = torch.as_tensor(channel_mask(vocab, default_aux_words(vocab, load_dataset(env.dataset))), device=device)

    def one_update():
        state = model.initial_state(B, device=device)
        buffer.set_initial_state(state)
        state = model.acting_state(state)  # as the sampler acts (a frame window's conv cache)
        with torch.no_grad():
            for t in range(T):  # acting: one batched step at a time, as in a rollout (through a graph: the sampler's)
                obs = {k: v[t : t + 1] for k, v in buffer.obs.items()}
                out, state = acting(learner.graphs, model, obs, state, buffer.episode_starts[t : t + 1])
                buffer.values[t] = out.value[0]
        buffer.compute_returns(torch.zeros(B, device=device), cfg.ppo.gamma, cfg.ppo.gae_lambda)
        learner.update(buffer, mask)

    def sync():
        if device.type == "cuda":
            torch.cuda.synchronize(device)

    with conv_precision(model, cfg.precision):
        one_update()  # warm-up
        sync()
        t0 = time.perf_counter()
        for _ in range(updates):
            one_update()
        sync()
    return updates * B * T / (time.perf_counter() - t0)


def _end_to_end(cfg, updates: int, stack: int = 1) -> tuple[float, dict]:
    """Frames/s of the trainer's own loop (real envs) over ``updates`` updates after a warm-up one, and its time
    split; with ``stack`` N > 1, of N seeds packed in one process (emml/rl/packed_trainer.py), all their frames
    counted. Writes nothing outside a temporary directory."""
    import dataclasses
    import tempfile

    from emml.rl.packed_trainer import PackedTrainer
    from emml.rl.trainer import Trainer

    with tempfile.TemporaryDirectory() as tmp:
        run = dataclasses.replace(
            cfg,
            frames=(updates + 1) * cfg.frames_per_update,
            eval_every=0,  # the training is measured, not its scoring: no evaluation, no final score
            score=False,
            checkpoint_every=10**6,
            log_every=10**6,
            run_root=tmp,
            results_root=tmp,
            table="bench",
        )
        run.env = dataclasses.replace(cfg.env)
        if stack > 1:
            trackers = [MemoryTracker() for _ in range(stack)]
            seeds = [dataclasses.replace(run, seed=s) for s in range(stack)]
            PackedTrainer(seeds, trackers=trackers, quiet=True).train()
            fps = [m["charts/packed_fps"] for _, m in trackers[0].history if "charts/packed_fps" in m][1:]
            return sum(fps) / len(fps), {}
        tracker = MemoryTracker()
        trainer = Trainer(run, tracker=tracker, quiet=True)
        trainer.train()
    measured = [m for _, m in tracker.history if "charts/fps" in m][1:]  # the first pays for warm-up (and compiling)
    return sum(m["charts/fps"] for m in measured) / len(measured), time_split(measured)


def time_split(metrics: list[dict]) -> dict[str, float]:
    """Each part's share of the time over these updates' metrics (the trainer's ``perf/<part>_s``)."""
    from emml.rl.progress import TIME_SPLIT, time_shares

    seconds = {part: sum(m[f"perf/{part}_s"] for m in metrics) for part in TIME_SPLIT}
    return {part: round(share, 3) for part, share in time_shares(seconds).items()}


def _raw_steps(config: DoomConfig, steps: int) -> float:
    """Raw engine steps/s of one process (the simulator alone, as in `bench env`)."""
    env = make_env(config)
    try:
        return _raw(env, steps, np.random.default_rng(0))[0]
    finally:
        env.close()


def _pool(n: int):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("forkserver"))


def simulator_limit(config: DoomConfig, processes: int, steps: int = 5000) -> float:
    """Aggregate raw engine steps/s of ``processes`` engines stepped at once: what the machine's cores can
    simulate at most, the ceiling of any number of packed runs."""
    with _pool(processes) as pool:
        return sum(pool.map(_raw_steps, [config] * processes, [steps] * processes))


PARTS = ("both", "model", "e2e")
"""What `bench train` measures: model-only and end-to-end (with their ratio), or one of them."""


def bench_train(
    cfg,
    updates: int = 5,
    runs: int = 0,
    limit_steps: int = 5000,
    part: str = "both",
    stack: int = 1,
    graphs: bool = False,
) -> dict:
    """Model-only vs end-to-end training frames/s for one config, measured in one run, with the end-to-end time
    split (simulate / infer / learn) per update; with double buffering on, the lockstep loop too. With ``runs``
    N > 0: N end-to-end runs packed side by side (each with cores/N torch threads), their aggregate frames/s, and
    the raw simulator limit of all cores. With ``stack`` N > 1: one run, then N seeds stacked in one model and one
    process (emml/rl/packed.py), measured in turn, their aggregate frames/s beside the one run's. With ``graphs``: one
    run plain, then with acting and the update captured as CUDA graphs (`TrainConfig.cuda_graphs`), in turn, and
    ``runs`` N > 0 packed runs captured."""
    import dataclasses

    from emml.models.compiled import wants_compile
    from emml.rl import alloc

    alloc.tune_glibc()  # as the trainer does: model-only and end-to-end measured on the same allocator
    if part not in PARTS:
        raise ValueError(f"part={part!r}: allowed values are {', '.join(PARTS)}")
    out = {
        "allocator": alloc.loaded(),
        "model": cfg.model,
        "aux": cfg.aux,
        "height": cfg.env.height,
        "width": cfg.env.width,
        "num_envs": cfg.num_envs,
        "num_steps": cfg.num_steps,
        "env_groups": cfg.env_groups,
        "device": cfg.device,
        "precision": cfg.precision,
        "compiled": wants_compile(cfg.compile, cfg.device),
        "updates": updates,
    }
    if graphs:  # one run plain, then captured, measured in turn; the packed runs captured
        plain, captured = (dataclasses.replace(cfg, cuda_graphs=on) for on in (False, True))
        out["graphs"] = {}
        for key, name, measure in (
            ("model_only", "model", _model_only),
            ("end_to_end", "e2e", lambda c, u: _end_to_end(c, u)[0]),
        ):
            if part in ("both", name):
                before, after = measure(plain, updates), measure(captured, updates)
                out["graphs"][key] = {"plain_fps": round(before, 1), "graphs_fps": round(after, 1)}
                out["graphs"][key]["gain"] = round(after / before, 3)
        if runs:
            out["packed"] = _packed(captured, updates, runs, limit_steps)
        return out
    if stack > 1:  # one run, then N seeds packed in one process, measured in turn
        out["stack"] = stack
        if part in ("both", "model"):
            single, stacked = _model_only(cfg, updates), _model_only(cfg, updates, stack)
            out |= {"model_only_fps": round(single, 1), "stacked_model_only_fps": round(stacked, 1)}
            out["stacked_model_only_gain"] = round(stacked / single, 3)
        if part in ("both", "e2e"):
            single, stacked = _end_to_end(cfg, updates)[0], _end_to_end(cfg, updates, stack)[0]
            out |= {"end_to_end_fps": round(single, 1), "stacked_end_to_end_fps": round(stacked, 1)}
            out["stacked_end_to_end_gain"] = round(stacked / single, 3)
        return out
    if part == "model":
        out["model_only_fps"] = round(_model_only(cfg, updates), 1)
        return out
    if part == "e2e":
        e2e, out["time_split"] = _end_to_end(cfg, updates)
        out["end_to_end_fps"] = round(e2e, 1)
        return out
    before = _model_only(cfg, updates)
    e2e, split = _end_to_end(cfg, updates)
    after = _model_only(cfg, updates)  # measured on both sides of the end-to-end run: this machine's speed drifts
    model_fps = (before + after) / 2
    out |= {
        "model_only_fps": round(model_fps, 1),
        "model_only_before_after": [round(before, 1), round(after, 1)],
        "end_to_end_fps": round(e2e, 1),
        "ratio": round(e2e / model_fps, 3),
        "time_split": split,
    }
    if cfg.env_groups > 1:
        lockstep, _ = _end_to_end(dataclasses.replace(cfg, env_groups=1), updates)
        out["lockstep_fps"] = round(lockstep, 1)
        out["double_buffer_gain"] = round(e2e / lockstep, 3)
    if runs:
        out["packed"] = _packed(cfg, updates, runs, limit_steps)
    return out


def _packed(cfg, updates: int, runs: int, limit_steps: int) -> dict:
    """``runs`` end-to-end runs side by side (each with cores/N torch threads): their aggregate frames/s against the
    raw simulator limit of all cores."""
    import dataclasses
    import os

    cores = os.cpu_count() or 1
    packed = dataclasses.replace(cfg, threads=max(1, cores // runs))
    with _pool(runs) as pool:
        per_run = [fps for fps, _ in pool.map(_end_to_end, [packed] * runs, [updates] * runs)]
    limit = simulator_limit(cfg.env, cores, limit_steps)
    return {
        "runs": runs,
        "threads_per_run": packed.threads,
        "cuda_graphs": cfg.cuda_graphs,
        "per_run_fps": [round(f, 1) for f in per_run],
        "aggregate_fps": round(sum(per_run), 1),
        "simulator_limit_fps": round(limit, 1),
        "fraction_of_limit": round(sum(per_run) / limit, 3),
        "cores": cores,
    }


def allocator_envs() -> dict[str, dict[str, str]]:
    """The allocators this machine can run, as environment overrides for a child process: tcmalloc (system
    package) and mimalloc (the `cmeel-mimalloc` wheel) only where installed, glibc tuned and untuned always."""
    import sysconfig

    from emml.rl import alloc

    envs = {}
    if alloc.tcmalloc_path():
        envs["tcmalloc"] = {"EMML_MALLOC": "tcmalloc"}
    mimalloc = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "lib" / "libmimalloc.so"
    if mimalloc.exists():
        envs["mimalloc"] = {"EMML_MALLOC": "glibc", "LD_PRELOAD": str(mimalloc)}
    envs["glibc-tuned"] = {"EMML_MALLOC": "glibc-tuned"}
    envs["glibc"] = {"EMML_MALLOC": "glibc"}
    return envs


def bench_variants(
    variants: dict[str, tuple[dict[str, str], list[str]]],
    train_args: list[str],
    rounds: int = 3,
    parts: tuple[str, ...] = ("model", "e2e"),
) -> dict:
    """`bench train --part P` for each variant (name → (environment overrides, extra `bench train` options)) in a
    child process, interleaved round by round so that the machine's drift falls on all of them alike; the median
    frames/s per variant and part, and each one's ratio to the best."""
    import json
    import os
    import subprocess
    import sys

    fps = {name: {part: [] for part in parts} for name in variants}
    children = {}
    for _ in range(rounds):
        for name, (extra_env, extra_args) in variants.items():
            env = {k: v for k, v in os.environ.items() if k != "LD_PRELOAD"} | extra_env
            for part in parts:
                cmd = [sys.executable, "-m", "emml.cli", "bench", "train", "--json", "--part", part]
                proc = subprocess.run([*cmd, *train_args, *extra_args], env=env, capture_output=True, text=True)
                if proc.returncode != 0:
                    raise RuntimeError(f"bench train ({name}) failed:\n{proc.stderr[-2000:]}")
                r = children[name] = json.loads(proc.stdout)
                fps[name][part].append(r["model_only_fps" if part == "model" else "end_to_end_fps"])
    median = {name: {part: float(np.median(v)) for part, v in d.items()} for name, d in fps.items()}
    best = {part: max(m[part] for m in median.values()) for part in parts}
    return {
        "rounds": rounds,
        "train_args": train_args,
        "allocators": {name: r["allocator"] for name, r in children.items()},
        "fps": fps,
        "median_fps": median,
        "ratio_to_best": {n: {p: round(m[p] / best[p], 3) for p in parts} for n, m in median.items()},
    }


def bench_alloc(train_args: list[str], rounds: int = 3, parts: tuple[str, ...] = ("model", "e2e")) -> dict:
    """`bench_variants` over the allocators this machine has (`allocator_envs`); fails if a child did not run on
    the allocator it was given."""
    r = bench_variants({name: (env, []) for name, env in allocator_envs().items()}, train_args, rounds, parts)
    wrong = {name: ran for name, ran in r["allocators"].items() if ran != name}
    if wrong:
        raise RuntimeError(f"children ran on other allocators than asked: {wrong}")
    return r


def bench_workers(train_args: list[str], per_worker: list[int], rounds: int = 3) -> dict:
    """End-to-end frames/s with each number of envs per worker process (`envs_per_worker`), interleaved."""
    variants = {f"{k} per worker": ({}, ["--set", f"envs_per_worker={k}"]) for k in per_worker}
    return bench_variants(variants, train_args, rounds, parts=("e2e",))
