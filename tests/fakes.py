"""The model interface the sampler, `evaluate.play` and the diagnostics call, for scripted test models.

A subclass writes only `forward`; the recurrent state is one zero per env and no frame window is carried, so there
is nothing for `acting_state` to cache or for `replay_state` to strip (`EmmlModel.acting_state`).
"""

from types import SimpleNamespace

import torch


class ScriptedModel(torch.nn.Module):
    """A stateless stand-in for `EmmlModel`: subclasses script `forward(obs, state, episode_start)`."""

    cfg = SimpleNamespace(x_image="sigmoid", control="none")
    """The `ModelConfig` fields the diagnostics read: x_I = sigmoid(conv3), no control."""

    def initial_state(self, n: int, device=None) -> dict:
        return {"h": torch.zeros(n, 1, device=device)}

    def acting_state(self, state: dict) -> dict:
        return state

    def replay_state(self, state: dict) -> dict:
        return state
