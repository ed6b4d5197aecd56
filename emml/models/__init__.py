"""Model zoo of "Embodied Multimodal Multitask Learning" (Chaplot et al. 2019,
arXiv 1902.01385): the Dual-Attention model, its ablations (Section 4) and
the fusion baselines of the appendix, all sharing one `EmmlModel` class.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from emml.models.config import ARCHITECTURES, ModelConfig
from emml.models.encoders import conv_output_size
from emml.models.policy import EmmlModel, ModelOutput


@dataclass(frozen=True)
class ModelSpec:
    """A registry entry: a fusion architecture plus config switches."""

    description: str
    """One-line description for `emml models`; '{x_S}' stands for the state the entry computes (`state_formula`)."""
    options: dict[str, Any] = field(default_factory=dict)
    """`ModelConfig` fields this entry sets (always includes `name`)."""


MODELS: dict[str, ModelSpec] = {
    "text_only": ModelSpec("Text only: x_S = [x_BoW, x_sent]", {"name": "text_only"}),
    "image_only": ModelSpec("Image only: x_S = vec(x_I)", {"name": "image_only"}),
    "concat": ModelSpec("Concat: x_S = [vec(x_I), x_BoW, x_sent]", {"name": "concat"}),
    "ga": ModelSpec("Gated-Attention: x_S = vec(x_I ⊙ x_sent)", {"name": "ga"}),
    "film": ModelSpec("FiLM: x_S = vec(gamma(x_sent) ⊙ x_I + beta(x_sent))", {"name": "film"}),
    "pacman": ModelSpec("PACMAN: QA attention over the last 5 frames", {"name": "pacman"}),
    "dual_attention": ModelSpec(
        "Dual-Attention (proposed): GA1 -> SA -> GA2, {x_S}",
        {"name": "dual_attention"},
    ),
    "da_no_sa": ModelSpec(
        "Dual-Attention w/o Spatial-Attention, {x_S}",
        {"name": "dual_attention", "spatial_attention": False},
    ),
    "da_no_ga1": ModelSpec("Dual-Attention w/o GA1 (no BoW gating), {x_S}", {"name": "dual_attention", "ga1": False}),
    "da_no_ga2": ModelSpec(
        "Dual-Attention w/o GA2 (no sentence gating), {x_S}", {"name": "dual_attention", "ga2": False}
    ),
    "da_no_indicator": ModelSpec(
        "Dual-Attention w/o task indicator, {x_S}", {"name": "dual_attention", "task_indicator": False}
    ),
}
"""Every buildable model name -> its `ModelSpec`."""


def model_config(name: str, **overrides: Any) -> ModelConfig:
    """The validated `ModelConfig` of registry entry `name`, with `overrides` applied."""
    if name not in MODELS:
        raise ValueError(f"unknown model name={name!r}; known names: " + ", ".join(MODELS))
    unknown = set(overrides) - set(ModelConfig.__dataclass_fields__)
    if unknown:
        raise ValueError(
            f"unknown ModelConfig field(s) {sorted(unknown)}; allowed: " + ", ".join(ModelConfig.__dataclass_fields__)
        )
    return replace(ModelConfig(), **{**MODELS[name].options, **overrides}).validate()


def state_formula(cfg: ModelConfig) -> str:
    """x_S as the code computes it for a Dual-Attention config (`DualAttention.forward`): the paper's vec(x_spat)
    (the text after Eq. 5), times h·w under `state_scale` (the default), a sharper gradient-stopped copy of the map
    under `state_temperature`; vec(x_GA1) without spatial attention. '' for the baselines (their entry says it)."""
    if cfg.name != "dual_attention":
        return ""
    if not cfg.spatial_attention:
        return "x_S = vec(x_GA1)"
    read = "vec(x_spat)" if cfg.state_temperature is None else f"softmax(scores / {cfg.state_temperature:g})"
    return f"x_S = h·w·{read}" if cfg.state_scale else f"x_S = {read}"


def describe(name: str, **overrides: Any) -> str:
    """Registry entry `name`'s description, with the x_S its config (and `overrides`) computes."""
    return MODELS[name].description.format(x_S=state_formula(model_config(name, **overrides)))


def build_model(name: str, vocab_size: int, height: int, width: int, max_steps: int, **overrides: Any) -> EmmlModel:
    """Build registry model `name` for a V-word vocabulary and (height, width) images."""
    return EmmlModel(model_config(name, **overrides), vocab_size, height, width, max_steps)


def count_parameters(model) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def model_table(vocab_size: int, height: int, width: int, max_steps: int) -> list[dict]:
    """[{name, description, parameters}] for every registry model."""
    return [
        {
            "name": name,
            "description": describe(name),
            "parameters": count_parameters(build_model(name, vocab_size, height, width, max_steps)),
        }
        for name in MODELS
    ]


__all__ = [
    "ARCHITECTURES",
    "MODELS",
    "EmmlModel",
    "ModelConfig",
    "ModelOutput",
    "ModelSpec",
    "build_model",
    "conv_output_size",
    "count_parameters",
    "describe",
    "model_config",
    "model_table",
    "state_formula",
]
