"""N Doom envs in worker processes, observations through shared memory (uint8), clean shutdown.

Gymnasium's AsyncVectorEnv does the protocol (step/reset/close over pipes, observations in shared memory).
What this module adds: workers that end their engine however they end — normal close, an exception, Ctrl-C,
SIGTERM, or the parent dying (the worker's pipe read fails, its `finally` closes the env) — and same-step
autoreset, so that a PPO rollout never holds a dummy transition: after an episode ends, the step returns the next
episode's first observation, and the ended episode's info under ``final_info``.
"""

from __future__ import annotations

import multiprocessing as mp
from dataclasses import asdict

from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv
from gymnasium.vector.async_vector_env import AsyncState

from emml.config import DoomConfig


def _make_env(config: dict):
    from emml.envs.doom import DoomEnv
    from emml.envs.engine import install_signal_handlers

    install_signal_handlers()  # in the worker: SIGTERM → SystemExit → the worker's finally closes the env
    return DoomEnv(DoomConfig(**config))


class _Closing:
    """Context manager protocol for the vector envs: ``with make_vector_env(...) as venv``."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


class AsyncDoomVectorEnv(_Closing, AsyncVectorEnv):
    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort()
        return False

    def abort(self) -> None:
        """End the workers without talking to them: after an interrupt (SIGTERM, Ctrl-C) the parent may have
        stopped in the middle of reading a message, and a graceful close would then wait forever on a pipe out
        of step. Each worker gets SIGTERM instead; its handler raises SystemExit and its `finally` ends its
        engine."""
        self._state = AsyncState.DEFAULT  # forget the pending call: its reply may be half read
        self.close(terminate=True)


class SyncDoomVectorEnv(_Closing, SyncVectorEnv):
    pass


class _EnvFactory:
    """Picklable env constructor (lambdas don't survive forkserver)."""

    def __init__(self, config: DoomConfig):
        self.config = asdict(config)

    def __call__(self):
        return _make_env(self.config)


def make_vector_env(config: DoomConfig, num_envs: int, asynchronous: bool = True):
    """``num_envs`` copies of the env. Asynchronous: one worker process each (forkserver: workers don't inherit
    the learner's torch threads or open files). Use it as a context manager, or call ``close()``."""
    config.validate()
    fns = [_EnvFactory(config) for _ in range(num_envs)]
    if not asynchronous:
        return SyncDoomVectorEnv(fns, autoreset_mode=AutoresetMode.SAME_STEP)
    return AsyncDoomVectorEnv(
        fns,
        shared_memory=True,
        context="forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn",
        daemon=True,
        autoreset_mode=AutoresetMode.SAME_STEP,
    )
