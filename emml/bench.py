"""`emml bench env`: throughput of our env against the raw engine it wraps, measured in one run.

Raw: the same DoomGame (same map and objects, resolution, buffers, tics per step) stepped with `make_action` +
`get_state`.
Ours: `DoomEnv.step` (action mapping, resize, labels, rewards, observation dict). Both with random moves; reset
time is measured apart (ours: sampling a scene, placing 5 objects; raw: `new_episode`). Then the vector env with
1 and 2 worker processes, resets included.
"""

from __future__ import annotations

import time

import numpy as np

from emml.config import DoomConfig
from emml.envs.doom import DoomEnv
from emml.envs.vector import make_vector_env


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
    """Steps/s of raw engine vs our env (labels off and on), and of the vector env with 1 and 2 workers."""
    rng = np.random.default_rng(0)
    out: dict = {"height": config.height, "width": config.width, "render": "x".join(map(str, config.render_size()))}
    for aux in (False, True):
        cfg = DoomConfig(**{**config.to_dict(), "aux_labels": aux})
        env = DoomEnv(cfg)
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
