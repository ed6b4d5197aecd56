"""Model zoo of "Embodied Multimodal Multitask Learning" (Chaplot et al. 2019,
arXiv 1902.01385): the Dual-Attention model, its ablations (Section 4) and
the fusion baselines of the appendix, all sharing one `EmmlModel` class; each model is declared once, in the
model registry (emml/models/registry.py), which plugins extend (emml/models/plugins.py).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from emml.config.schema import ModelConfig
from emml.models.encoders import conv_output_size
from emml.models.fusion import Fusion, FusionOutput
from emml.models.policy import EmmlModel, ModelOutput
from emml.models.registry import (
    ARCHITECTURES,
    MODELS,
    PLUGIN_HINT,
    ModelSpec,
    check_architecture,
    register_model,
    register_variant,
)


def model_config(name: str, **overrides: Any) -> ModelConfig:
    """The validated `ModelConfig` of registry entry `name`, with `overrides` applied."""
    if name not in MODELS:
        raise ValueError(f"unknown model name={name!r}; known names: {', '.join(MODELS)}; {PLUGIN_HINT}")
    spec = MODELS[name]
    unknown = set(spec.switches) - set(ModelConfig.__dataclass_fields__)
    if unknown:  # a plugin's entry
        raise ValueError(
            f"model {name!r} (registered by {spec.source}) sets unknown ModelConfig field(s) {sorted(unknown)}; "
            "allowed: " + ", ".join(ModelConfig.__dataclass_fields__)
        )
    unknown = set(overrides) - set(ModelConfig.__dataclass_fields__)
    if unknown:
        raise ValueError(
            f"unknown ModelConfig field(s) {sorted(unknown)}; allowed: " + ", ".join(ModelConfig.__dataclass_fields__)
        )
    return check_architecture(replace(ModelConfig(), **{**spec.options, **overrides}).validate())


def state_formula(cfg: ModelConfig) -> str:
    """x_S as the code computes it for `cfg` (its fusion's `state_formula`; Dual-Attention:
    `DualAttention.state_formula`); '' where the registry entry's description says it."""
    return MODELS[cfg.name].fusion.state_formula(cfg) if cfg.name in MODELS else ""


def describe(name: str, **overrides: Any) -> str:
    """Registry entry `name`'s description, with the x_S its config (and `overrides`) computes."""
    return MODELS[name].description.replace("{x_S}", state_formula(model_config(name, **overrides)))


def build_model(name: str, vocab_size: int, height: int, width: int, max_steps: int, **overrides: Any) -> EmmlModel:
    """Build registry model `name` for a V-word vocabulary and (height, width) images."""
    return EmmlModel(model_config(name, **overrides), vocab_size, height, width, max_steps)


def count_parameters(model) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def model_table(vocab_size: int, height: int, width: int, max_steps: int) -> list[dict]:
    """[{name, description, parameters, source}] for every registry model (plugins' included)."""
    return [
        {
            "name": name,
            "description": describe(name),
            "parameters": count_parameters(build_model(name, vocab_size, height, width, max_steps)),
            "source": spec.source,
        }
        for name, spec in MODELS.items()
    ]


__all__ = [
    "ARCHITECTURES",
    "MODELS",
    "EmmlModel",
    "Fusion",
    "FusionOutput",
    "ModelConfig",
    "ModelOutput",
    "ModelSpec",
    "build_model",
    "check_architecture",
    "conv_output_size",
    "count_parameters",
    "describe",
    "model_config",
    "model_table",
    "register_model",
    "register_variant",
    "state_formula",
]
