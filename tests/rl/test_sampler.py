"""The double-buffered sampler stores exactly what plain envs produce, and survives engine deaths."""

from __future__ import annotations

import contextlib
import os
import signal
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from emml.config.schema import DoomConfig, TrainConfig
from emml.envs.doom import DoomEnv
from emml.envs.engine import EngineError
from emml.rl.rollout import RolloutBuffer
from emml.rl.sampler import Sampler
from tests.conftest import SMOKE
from tests.fakes import ScriptedModel


class CountingPolicy(ScriptedModel):
    """Uniformly random moves, answer word 0, and a state that counts the steps since the episode started."""

    def __init__(self, vocab_size: int):
        super().__init__()
        self.V = vocab_size

    def forward(self, obs, state, episode_start):
        T, B = obs["task"].shape
        h = torch.where(episode_start[-1].unsqueeze(-1), torch.zeros_like(state["h"]), state["h"]) + 1
        out = SimpleNamespace(
            logits=torch.zeros(T, B, 4), answer_logits=torch.zeros(T, B, self.V), value=torch.zeros(T, B)
        )
        return out, {"h": h}


def _config(groups: int, **fields) -> TrainConfig:
    cfg = TrainConfig(**{"aux": True, "num_envs": 4, "num_steps": 40, "env_groups": groups, **fields})
    cfg.env = DoomConfig(aux_labels=True, **SMOKE)
    return cfg.validate()


def _buffer(sampler, cfg):
    shapes = {
        k: (s.shape, torch.uint8 if s.dtype == np.uint8 else torch.int64)
        for k, s in sampler.single_observation_space.spaces.items()
    }
    return RolloutBuffer(cfg.num_steps, cfg.num_envs, shapes)


@pytest.mark.parametrize("groups,asynchronous", [(1, True), (2, True), (2, False)])
def test_rollouts_hold_exactly_what_plain_envs_produce(groups, asynchronous, no_leftovers):
    cfg = _config(groups, asynchronous=asynchronous)  # asynchronous=False: the envs in this process
    torch.manual_seed(0)
    rollouts = []
    with Sampler(cfg, torch.device("cpu")) as sampler:
        V = int(sampler.single_observation_space["tokens"].high.max())
        model = CountingPolicy(V + 1)
        buffer = _buffer(sampler, cfg)
        sampler.reset(model, seed=100)
        for _ in range(2):  # two rollouts: the state and the envs carry across the boundary
            sampler.collect(model, buffer)
            rollouts.append(
                {
                    "obs": {k: v.clone() for k, v in buffer.obs.items()},
                    "actions": buffer.actions.clone(),
                    "rewards": buffer.rewards.clone(),
                    "dones": buffer.dones.clone(),
                    "starts": buffer.episode_starts.clone(),
                    "h0": buffer.initial_state["h"].clone(),
                }
            )
        final_h = sampler.state["h"].clone()
    assert any(r["dones"].any() for r in rollouts), "no episode ended: the autoreset path went untested"
    for i in range(cfg.num_envs):
        env = DoomEnv(cfg.env)
        try:
            obs, _ = env.reset(seed=100 + i)
            start, since = True, 0.0
            for r in rollouts:
                assert r["h0"][i, 0] == since  # the recurrent state of actor i crossed the boundary intact
                for t in range(cfg.num_steps):
                    for key, value in obs.items():
                        assert np.array_equal(r["obs"][key][t, i].numpy(), np.asarray(value)), (key, t, i)
                    assert bool(r["starts"][t, i]) == start
                    since = 1.0 if start else since + 1
                    obs, reward, terminated, truncated, _ = env.step(np.array([int(r["actions"][t, i]), 0]))
                    done = terminated or truncated
                    assert r["rewards"][t, i].item() == pytest.approx(reward, abs=1e-6)
                    assert bool(r["dones"][t, i]) == done
                    if done:
                        obs, _ = env.reset()  # same-step autoreset, as the worker does it
                    start = done
            assert final_h[i, 0] == since
        finally:
            env.close()


@contextlib.contextmanager
def _started(cfg):
    """A sampler with every actor reset (seed 0): yields (sampler, policy, buffer); closed on the way out."""
    with Sampler(cfg, torch.device("cpu")) as sampler:
        model = CountingPolicy(32)
        sampler.reset(model, seed=0)
        yield sampler, model, _buffer(sampler, cfg)


def _kill_engine(sampler, group: int = 0) -> int:
    pid = sampler.venvs[group].get_attr("engine_pid")[0]
    os.kill(pid, signal.SIGKILL)
    return pid


def test_a_dead_engine_is_restarted_and_its_episode_dropped(no_leftovers, caplog):
    with _started(_config(2, num_envs=2)) as (sampler, model, buffer):
        sampler.collect(model, buffer)
        before = sampler.venvs[0].get_attr("engine_pid")[0]
        killed = _kill_engine(sampler)
        sampler.collect(model, buffer)  # goes on: the worker started a new engine
        assert sampler.dropped_episodes == 1
        assert "ViZDoom engine of actor 0 died: restarted, its episode dropped (1 dropped" in caplog.text  # at once
        assert sampler.venvs[0].get_attr("engine_restarts") == (1,)
        after = sampler.venvs[0].get_attr("engine_pid")[0]
        assert killed == before and after not in (None, before)
        assert buffer.dones[:, 0].any()  # the dropped episode ended as truncated
        sampler.collect(model, buffer)
        assert sampler.dropped_episodes == 1


def test_repeated_engine_deaths_end_the_run_with_a_clear_error(no_leftovers):
    with pytest.raises(EngineError, match="engine died 2 times in a row"):
        with _started(_config(2, num_envs=2, max_engine_restarts=1)) as (sampler, model, buffer):
            for _ in range(3):
                _kill_engine(sampler)
                sampler.collect(model, buffer)


def test_env_groups_must_divide_the_actors():
    with pytest.raises(ValueError, match="env_groups=3 must be a positive divisor of num_envs=8"):
        TrainConfig(env_groups=3).validate()


def test_a_killed_worker_process_is_replaced_and_its_group_restarted(no_leftovers, caplog):
    with _started(_config(2, num_envs=4)) as (sampler, model, buffer):
        sampler.collect(model, buffer)
        old = [p.pid for p in sampler.venvs[1].processes]
        os.kill(old[0], signal.SIGKILL)  # its engine is orphaned: the sampler must end it
        sampler.collect(model, buffer)
        assert sampler.workers.restarts == 1 and sampler.dropped_episodes == 2  # the group's 2 episodes
        assert "env worker of group 1 died" in caplog.text and "2 episodes dropped" in caplog.text
        assert not set(old) & {p.pid for p in sampler.venvs[1].processes}
        assert all(p.is_alive() for p in sampler.venvs[1].processes)
        sampler.collect(model, buffer)
        assert sampler.workers.restarts == 1


def test_sample_moves_draws_and_scores_as_categorical_bit_for_bit():
    from emml.rl.sampler import sample_moves

    logits = torch.randn(64, 4, generator=torch.Generator().manual_seed(0)) * 3
    torch.manual_seed(7)
    dist = torch.distributions.Categorical(logits=logits)
    want_move = dist.sample()
    want_log_prob = dist.log_prob(want_move)
    torch.manual_seed(7)
    move, log_prob = sample_moves(logits)
    assert torch.equal(move, want_move) and torch.equal(log_prob, want_log_prob)
