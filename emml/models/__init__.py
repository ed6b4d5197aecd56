"""Model zoo of "Embodied Multimodal Multitask Learning" (Chaplot et al. 2019,
arXiv 1902.01385): the Dual-Attention model, its ablations (Section 4) and
the fusion baselines of the appendix, all sharing one `EmmlModel` class; each model is declared once, in the
model registry (emml/models/registry.py), which plugins extend (emml/models/plugins.py).
"""

from __future__ import annotations

from typing import Any

from emml.config.schema import ModelConfig, check_model_options, model_option, option_fields
from emml.models.encoders import conv_output_size
from emml.models.fusion import Fusion, FusionOptions, FusionOutput
from emml.models.policy import EmmlModel, ModelOutput
from emml.models.registry import (
    ARCHITECTURES,
    MODELS,
    PLUGIN_HINT,
    ModelSpec,
    check_architecture,
    fusion_options,
    register_model,
    register_variant,
)


def model_config(name: str, **overrides: Any) -> ModelConfig:
    """The validated `ModelConfig` of registry entry `name`, with `overrides` (`TrainConfig.model_options`) applied:
    each one an option every model shares (`ModelConfig`) or one its fusion declares (`Fusion.options`); an unknown
    name fails in one line naming it and the model's options, a bad value naming the field."""
    if name not in MODELS:
        raise ValueError(f"unknown model name={name!r}; known names: {', '.join(MODELS)}; {PLUGIN_HINT}")
    spec = MODELS[name]
    declared, shared = spec.fusion.options, option_fields(ModelConfig)
    allowed = [*shared, *option_fields(declared)]
    unknown = sorted(set(spec.switches) - set(allowed))
    if unknown:  # a plugin's entry
        raise ValueError(
            f"model {name!r} (registered by {spec.source}) sets unknown option(s) {unknown}; allowed: "
            + ", ".join(allowed)
        )
    unknown = sorted(set(overrides) - set(allowed), key=str)
    if unknown:
        what = f"{unknown[0]!r} is not an option" if len(unknown) == 1 else f"{unknown} are not options"
        raise ValueError(f"model_options: {what} of model {name!r}; its options: " + ", ".join(allowed))
    values = {**spec.switches, **overrides}
    own = check_model_options(declared, {k: v for k, v in values.items() if k not in shared})
    cfg = ModelConfig(name=spec.architecture, **{k: v for k, v in values.items() if k in shared}, options=own)
    return check_architecture(cfg.validate())


def model_options(name: str) -> dict[str, Any]:
    """Registry model ``name``'s options and their values (its entry's switches over the defaults): the shared ones
    (`ModelConfig`), then its fusion's own (`Fusion.options`)."""
    cfg = model_config(name)
    return {
        **{k: getattr(cfg, k) for k in option_fields(ModelConfig)},
        **{k: getattr(cfg.options, k) for k in option_fields(type(cfg.options))},
    }


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
    """[{name, description, parameters, source, options}] for every registry model (plugins' included); options: its
    fusion's own (`Fusion.options`) with the entry's values, those a run may set beside the shared ones."""
    return [
        {
            "name": name,
            "description": describe(name),
            "parameters": count_parameters(build_model(name, vocab_size, height, width, max_steps)),
            "source": spec.source,
            "options": {k: v for k, v in model_options(name).items() if k not in option_fields(ModelConfig)},
        }
        for name, spec in MODELS.items()
    ]


__all__ = [
    "ARCHITECTURES",
    "MODELS",
    "EmmlModel",
    "Fusion",
    "FusionOptions",
    "FusionOutput",
    "ModelConfig",
    "ModelOutput",
    "ModelSpec",
    "build_model",
    "check_architecture",
    "conv_output_size",
    "count_parameters",
    "describe",
    "fusion_options",
    "model_config",
    "model_option",
    "model_options",
    "model_table",
    "register_model",
    "register_variant",
    "state_formula",
]
