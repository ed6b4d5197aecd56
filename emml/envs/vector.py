"""N Doom envs in worker processes, observations through shared memory (uint8), clean shutdown, engine restarts.

Gymnasium's AsyncVectorEnv does the protocol (step/reset/close over pipes, observations in shared memory).
What this module adds: workers that end their engine however they end — normal close, an exception, Ctrl-C,
SIGTERM, or the parent dying (the worker's pipe read fails, its `finally` closes the env) — same-step
autoreset, so that a PPO rollout never holds a dummy transition: after an episode ends, the step returns the next
episode's first observation, and the ended episode's info under ``final_info`` — and engine restarts: a worker
whose engine dies starts a new one and goes on (`RestartingEnv`).
"""

from __future__ import annotations

import multiprocessing as mp
import time
from concurrent.futures import ThreadPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import asdict

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import load_env_creator
from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv
from gymnasium.vector.async_vector_env import AsyncState
from gymnasium.vector.utils import iterate

from emml.config.schema import DoomConfig, env_config_class
from emml.envs.engine import (
    EngineError,
    RestartBudget,
    WorkerDied,
    become_subreaper,
    end_orphan_engines,
    private_mp_tempdir,
)


class RestartingEnv(gym.Wrapper):
    """Survives engine deaths: when a step finds the engine dead, the episode in flight is dropped — it ends
    there as truncated, with reward 0 and ``engine_restart=True`` in its info, so that the trainer leaves it out
    of the success rates and counts it — and the next reset (same-step autoreset: at once) starts a new engine.
    ``max_restarts`` deaths in a row, each less than ``window`` steps after the previous restart, raise
    EngineError: an engine that cannot stay up ends the run with a clear error instead of looping.

    Every info carries ``engine_restart`` (False normally) so that batched infos have the key for every env."""

    def __init__(self, env, max_restarts: int = 3, window: int = 1000):
        super().__init__(env)
        self.budget = RestartBudget(max_restarts, window, "engine")
        self._blank = {k: np.zeros(s.shape, s.dtype) for k, s in env.observation_space.spaces.items()}

    @property
    def engine_restarts(self) -> int:
        """Engines this worker restarted (all of the run)."""
        return self.budget.restarts

    @property
    def engine_pid(self) -> int | None:
        """The pid of this env's engine process (None before the first reset)."""
        engine = self.env.unwrapped._engine
        return engine.pid if engine is not None else None

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        info["engine_restart"] = False
        return obs, info

    def step(self, action):
        try:
            obs, reward, terminated, truncated, info = self.env.step(action)
        except EngineError as e:
            self.env.close()  # ends what is left of the dead engine: its pid, its shm files (idempotent)
            self.budget.death(e)
            episode = self.env.unwrapped
            info = {"task": episode.task_id, "answer": episode.answer_id, "success": False, "engine_restart": True}
            return self._blank, 0.0, False, True, info
        self.budget.step()
        info["engine_restart"] = False
        return obs, reward, terminated, truncated, info


def make_env(config: DoomConfig | dict) -> gym.Env:
    """The env a config describes: the config class of its difficulty's env kind (emml/config/env_kinds.py), and the env
    class that config's gym id is registered with (a HouseEnv for 'house', HouseConfig; else a DoomEnv)."""
    values = asdict(config) if not isinstance(config, dict) else config
    cls = env_config_class(values.get("difficulty", "easy"))
    return env_class(cls.GYM_ID)(cls(**values))


def env_class(gym_id: str) -> type[gym.Env]:
    """The class ``gym_id`` is registered with (`import emml` registers the ids of emml/config/env_kinds.py), imported
    only now: a worker imports the one env it plays."""
    return load_env_creator(gym.spec(gym_id).entry_point)


def _make_env(config: dict, max_restarts: int, window: int):
    from emml.envs.engine import install_signal_handlers

    install_signal_handlers()  # in the worker: SIGTERM → SystemExit → the worker's finally closes the env
    import cv2

    cv2.setNumThreads(1)  # parallelism comes from one process per env: a resize thread pool per worker only thrashes
    return RestartingEnv(make_env(config), max_restarts, window)


class _Closing:
    """Context manager protocol for the vector envs: ``with make_vector_env(...) as venv``."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


class AsyncDoomVectorEnv(_Closing, AsyncVectorEnv):
    """Gymnasium's AsyncVectorEnv, plus: a dead worker is noticed (`WorkerDied`) instead of waited on forever
    — its orphaned engine keeps the pipe open — and closing ends the engines that dead workers left behind."""

    poll_interval = 0.5
    """Seconds between liveness checks of the workers while waiting on them."""

    def __init__(self, *args, **kwargs):
        become_subreaper()  # before the workers start: engines of workers that die are then adopted by us
        super().__init__(*args, **kwargs)

    def _poll_pipe_envs(self, timeout: float | None = None) -> bool:
        self._assert_is_running()
        deadline = None if timeout is None else time.monotonic() + timeout
        for index, (pipe, process) in enumerate(zip(self.parent_pipes, self.processes)):
            if pipe is None or pipe.closed:
                return False
            while True:
                left = self.poll_interval if deadline is None else min(self.poll_interval, deadline - time.monotonic())
                if pipe.poll(max(left, 0)):
                    break
                if not process.is_alive():
                    self._state = AsyncState.DEFAULT
                    raise _worker_died(index, process)
                if deadline is not None and time.monotonic() >= deadline:
                    return False
        return True

    @contextmanager
    def _broken_pipe(self):
        """A pipe that breaks in the block (EOF, or a reset when the worker died with our message unread) raised as
        the `WorkerDied` it means, naming the dead worker."""
        try:
            yield
        except (EOFError, ConnectionError) as e:
            self._state = AsyncState.DEFAULT
            deadline = time.monotonic() + 2  # the pipe breaks as the process ends: give is_alive a moment to agree
            while time.monotonic() < deadline:
                dead = next(((i, p) for i, p in enumerate(self.processes) if not p.is_alive()), None)
                if dead is not None:
                    raise _worker_died(*dead) from e
                time.sleep(0.05)
            raise WorkerDied(f"an env worker's pipe broke ({type(e).__name__}: {e})") from e

    def step_async(self, actions) -> None:
        with self._broken_pipe():
            super().step_async(actions)

    def step_wait(self, timeout: float | None = None):
        with self._broken_pipe():
            return super().step_wait(timeout)

    def reset_wait(self, timeout: float | None = None):
        with self._broken_pipe():
            return super().reset_wait(timeout)

    def close_extras(self, timeout: float | None = None, terminate: bool = False) -> None:
        terminate = terminate or not all(p.is_alive() for p in self.processes)  # a dead one would never answer
        if terminate:  # the workers are ended, not asked: a pending call's reply is not waited for
            self._state = AsyncState.DEFAULT
        try:
            try:
                super().close_extras(timeout, terminate)
            except WorkerDied:  # a worker died while the pending call was waited for: end the others
                self._state = AsyncState.DEFAULT
                super().close_extras(timeout, terminate=True)
        finally:
            end_orphan_engines()

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


def _worker_died(index: int, process) -> WorkerDied:
    return WorkerDied(f"env worker {index} (pid {process.pid}) died with exit code {process.exitcode}")


class SyncDoomVectorEnv(_Closing, SyncVectorEnv):
    """The envs in this process, stepped in turn (``asynchronous=False``: for debugging, one process to step
    through). ``step_async``/``step_wait`` as AsyncVectorEnv has them, so the sampler drives either: the step runs
    in ``step_wait``."""

    def step_async(self, actions) -> None:
        self._actions = np.array(actions)  # a copy: the caller may reuse its array before step_wait

    def step_wait(self, **kwargs):
        actions, self._actions = self._actions, None
        return self.step(actions)


class _Ahead(gym.Wrapper):
    """One env of a `ThreadedSyncVectorEnv`: its step, and the autoreset that follows when the step ends the
    episode, run on a pool thread ahead of SyncVectorEnv's serial loop, which then collects them in order."""

    def __init__(self, env):
        super().__init__(env)
        self._pending = None
        self._reset = None

    def launch(self, pool, action) -> None:
        self._pending = pool.submit(self._step_and_reset, action)

    def _step_and_reset(self, action):
        out = self.env.step(action)
        return out, (self.env.reset() if out[2] or out[3] else None)

    def settle(self) -> None:
        """Wait for the step in flight, if any, and forget it and its result."""
        future, self._pending, self._reset = self._pending, None, None
        if future is not None:
            wait([future])

    def step(self, action):
        if self._pending is None:
            return self.env.step(action)
        future, self._pending = self._pending, None
        out, self._reset = future.result()
        return out

    def reset(self, **kwargs):
        ahead, self._reset = self._reset, None
        if ahead is not None and not kwargs:  # SyncVectorEnv's same-step autoreset: already done on the thread
            return ahead
        return self.env.reset(**kwargs)


class ThreadedSyncVectorEnv(SyncDoomVectorEnv):
    """A SyncVectorEnv whose k envs step at once, one pool thread each. ViZDoom releases the GIL while its engine
    runs a step, so k engines simulate in parallel where SyncVectorEnv would wait on them one after another
    (measured on 2 cores: 2 engines stepped from 2 threads ×2.7 faster than in turn). Each env is stepped by one
    thread at a time and owns its engine and RNG, so the results are those of stepping in turn, bit for bit."""

    def __init__(self, env_fns, **kwargs):
        super().__init__([lambda fn=fn: _Ahead(fn()) for fn in env_fns], **kwargs)
        self._pool = ThreadPoolExecutor(max_workers=len(self.envs), thread_name_prefix="env")

    def step(self, actions):
        for env, action in zip(self.envs, iterate(self.action_space, actions), strict=True):
            env.launch(self._pool, action)
        try:
            return super().step(actions)
        except BaseException:
            for env in self.envs:  # let the other envs' steps end: no env may be stepped by two threads after this
                env.settle()
            raise

    def close_extras(self, **kwargs):
        self._pool.shutdown(wait=True, cancel_futures=True)  # no thread may be inside an env that closes
        super().close_extras(**kwargs)


class EnvBatch(gym.Env):
    """k envs hosted by one worker process, stepped at once (`ThreadedSyncVectorEnv`, same-step autoreset each),
    seen by gymnasium's AsyncVectorEnv as one env with batched spaces: its observation is (k, ...), its action
    (k, 2). So that the worker's own autoreset never fires, ``terminated``/``truncated`` are False and the per-env
    flags travel in the info (``terminated``, ``truncated``), with ``final_info`` as k-long arrays (zeros where no
    episode ended). `GroupedDoomVectorEnv` undoes the batching."""

    def __init__(self, venv: SyncVectorEnv):
        self.venv = venv
        self.observation_space = venv.observation_space
        self.action_space = venv.action_space

    def reset(self, *, seed=None, options=None):
        obs, info = self.venv.reset(seed=None if seed is None else list(seed), options=options)
        return obs, _unmasked(info)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.venv.step(action)
        out = _unmasked(info)
        out["terminated"], out["truncated"] = terminated, truncated
        return obs, reward, False, False, out

    def close(self):
        self.venv.close()


def _unmasked(info: dict) -> dict:
    """A vector env's info without gymnasium's ``_key`` masks (the outer vector env adds its own) or final_obs."""
    return {k: _unmasked(v) if isinstance(v, dict) else v for k, v in info.items() if k[0] != "_" and k != "final_obs"}


class GroupedDoomVectorEnv(_Closing, gym.vector.VectorEnv):
    """N = W·k envs in W worker processes of k envs each (`EnvBatch`): the same envs, seeds and same-step
    autoreset as one worker per env, with W instead of N processes to wake at every step; each worker steps its k
    engines at once (`ThreadedSyncVectorEnv`). See docs/throughput.md for what it gains where."""

    def __init__(self, workers: AsyncDoomVectorEnv, envs_per_worker: int, single_env: gym.Env):
        """``single_env``: an env of the same config, for its spaces (a DoomEnv starts no engine until reset)."""
        self.workers, self.k = workers, envs_per_worker
        self.num_envs = workers.num_envs * envs_per_worker
        self.single_observation_space = single_env.observation_space
        self.single_action_space = single_env.action_space
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, self.num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, self.num_envs)

    def _flat(self, tree):
        """(W, k, ...) leaves → (W·k, ...), views where the input is contiguous; the outer ``_key`` masks dropped."""
        if isinstance(tree, dict):
            return {key: self._flat(v) for key, v in tree.items() if key[0] != "_"}
        return tree.reshape(self.num_envs, *tree.shape[2:])

    def reset(self, *, seed=None, options=None):
        if isinstance(seed, int):
            seed = [seed + i for i in range(self.num_envs)]
        if seed is not None:
            seed = [tuple(seed[w * self.k : (w + 1) * self.k]) for w in range(self.workers.num_envs)]
        obs, info = self.workers.reset(seed=seed, options=options)
        return self._flat(obs), self._flat(info)

    def step_async(self, actions) -> None:
        self.workers.step_async(np.asarray(actions).reshape(self.workers.num_envs, self.k, -1))

    def step_wait(self, **kwargs):
        obs, reward, _, _, info = self.workers.step_wait(**kwargs)
        info = self._flat(info)
        terminated, truncated = info.pop("terminated"), info.pop("truncated")
        return self._flat(obs), reward.reshape(-1), terminated, truncated, info

    def step(self, actions):
        self.step_async(actions)
        return self.step_wait()

    def close(self, **kwargs) -> None:
        self.workers.close(**kwargs)

    def abort(self) -> None:
        self.workers.abort()

    def __exit__(self, exc_type, exc, tb):
        return self.workers.__exit__(exc_type, exc, tb)  # an exception aborts the workers: see abort

    @property
    def processes(self):
        return self.workers.processes


class _EnvFactory:
    """Picklable env constructor (lambdas don't survive forkserver); with ``k`` > 1 an `EnvBatch` of k envs."""

    def __init__(self, config: DoomConfig, max_restarts: int, window: int, k: int = 1):
        self.config = asdict(config)
        self.max_restarts = max_restarts
        self.window = window
        self.k = k

    def _one(self):
        return _make_env(self.config, self.max_restarts, self.window)

    def __call__(self):
        if self.k == 1:
            return self._one()
        fns = [self._one] * self.k
        return EnvBatch(ThreadedSyncVectorEnv(fns, autoreset_mode=AutoresetMode.SAME_STEP, copy=False))


def make_vector_env(
    config: DoomConfig,
    num_envs: int,
    asynchronous: bool = True,
    copy: bool = True,
    max_restarts: int = 3,
    restart_window: int = 1000,
    envs_per_worker: int = 1,
):
    """``num_envs`` copies of the env. Asynchronous: one worker process per ``envs_per_worker`` envs (forkserver:
    workers don't inherit the learner's torch threads or open files). Use it as a context manager, or call
    ``close()``.

    ``copy=False`` returns observations as views of the shared buffers (no copy): valid until the next step of
    this vector env. ``max_restarts``/``restart_window``: see `RestartingEnv`."""
    config.validate()
    k = envs_per_worker
    if k < 1 or num_envs % k:
        raise ValueError(f"envs_per_worker={k!r} must be a positive divisor of num_envs={num_envs}")
    if not asynchronous:
        fns = [_EnvFactory(config, max_restarts, restart_window) for _ in range(num_envs)]
        return SyncDoomVectorEnv(fns, autoreset_mode=AutoresetMode.SAME_STEP, copy=copy)
    private_mp_tempdir()
    fns = [_EnvFactory(config, max_restarts, restart_window, k) for _ in range(num_envs // k)]
    workers = AsyncDoomVectorEnv(
        fns,
        copy=copy,
        shared_memory=True,
        context="forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn",
        daemon=True,
        autoreset_mode=AutoresetMode.SAME_STEP,
    )
    if k == 1:
        return workers
    return GroupedDoomVectorEnv(workers, k, make_env(config))
