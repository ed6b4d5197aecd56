"""The envelope of every greedy play (emml.eval.evaluate.playing)."""

from __future__ import annotations

import pytest
from torch import nn

from emml.eval.evaluate import playing


class _Env:
    def __init__(self, cfg, closed: list):
        self.cfg, self._closed = cfg, closed

    def close(self):
        self._closed.append(self)


@pytest.mark.parametrize("fail_in", ["body", "third_env"])
def test_an_error_closes_every_env_made_and_restores_the_training_mode(fail_in):
    closed, made = [], []
    model = nn.Linear(2, 2).train()

    def make(cfg):
        if fail_in == "third_env" and len(made) == 2:
            raise RuntimeError("engine did not start")
        made.append(_Env(cfg, closed))
        return made[-1]

    with pytest.raises(RuntimeError):
        with playing(model, "cfg", 3, make=make) as envs:
            assert not model.training and len(envs) == 3
            raise RuntimeError("episode failed")
    assert closed == made and len(made) in (2, 3) and model.training


def test_an_eval_mode_model_stays_in_eval_mode():
    model = nn.Linear(2, 2).eval()
    with playing(model, "cfg", 1, make=lambda cfg: _Env(cfg, [])) as (env,):
        assert env.cfg == "cfg"
    assert not model.training
