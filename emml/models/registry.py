"""The model registry: every model the harness can build, declared once.

A model is a fusion architecture (a `Fusion` subclass: how x_I, x_BoW and x_sent become x_S and the answer logits,
and the options it declares, `Fusion.options`) plus the option values it sets; an ablation of Section 4 is a variant,
the same architecture with switches (Dual-Attention's options spatial_attention, ga1, ga2, or the shared
task_indicator).
The paper's models are the entries at the bottom of this module. A model of one's own registers from its own module,
loaded as a plugin (emml/models/plugins.py), with the same call::

    @register_model("toy", "Toy: x_S = vec(x_I ⊙ x_BoW)")
    class Toy(Fusion): ...

Every list of models derives from here: `MODELS` (`emml models`, `emml train --model`, a table row's `model`),
`ARCHITECTURES` (the names `ModelConfig.name` accepts) and `build_fusion`. Reading `MODELS` or `ARCHITECTURES` first
loads the plugins, once per process; registering does not.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any, TypeVar

from emml.config.schema import ModelConfig, check_model_options, option_fields
from emml.models import plugins
from emml.models.baselines import Concat, FiLM, GatedAttention, ImageOnly, Pacman, TextOnly
from emml.models.fusion import DualAttention, Fusion

F = TypeVar("F", bound=type[Fusion])

PLUGIN_HINT = (
    "a plugin's model is known once its plugin is loaded: emml --plugin PATH_OR_MODULE …, or the EMML_PLUGINS "
    "environment variable (docs/own-model.md)"
)
"""Said with every unknown model name: the model may be a plugin's, not loaded in this process."""


@dataclass(frozen=True)
class ModelSpec:
    """A registry entry: a fusion architecture plus `ModelConfig` switches."""

    name: str
    """Registry name: `emml train --model NAME`, a table row's `model`, a row of `emml models`."""
    description: str
    """One line for `emml models`; '{x_S}' stands for the state its config computes (`Fusion.state_formula`)."""
    architecture: str
    """The fusion architecture it builds, its `ModelConfig.name`: its own name, or the entry it is a variant of."""
    fusion: type[Fusion]
    """The fusion class; `EmmlModel` reads what it needs (a frame window, x_sent, …) from its attributes."""
    switches: Mapping[str, Any] = field(default_factory=dict)
    """Option values it sets: shared ones (`ModelConfig`) or its fusion's own (`Fusion.options`), e.g.
    {'spatial_attention': False} for 'w/o SA' (checked when the model's config is built, `emml.models.model_config`)."""
    source: str = "emml"
    """Who registered it: 'emml' (the paper's models), or the plugin (its file, or its module)."""

    @property
    def options(self) -> dict[str, Any]:
        """The option values the entry sets, and `name`, its architecture."""
        return {"name": self.architecture, **self.switches}


_ENTRIES: dict[str, ModelSpec] = {}
"""Registry name -> entry, in registration order (the paper's models first)."""


def _source(module: str) -> str:
    """'emml' for the package's own modules, else the plugin's: its file for one loaded from a path, or its module."""
    import sys

    if module == "emml" or module.startswith("emml."):
        return "emml"
    file = getattr(sys.modules.get(module), "__file__", None)
    return file if module.startswith("emml_plugin_") and file else module


def _add(spec: ModelSpec) -> ModelSpec:
    """Add `spec`; registering the same entry again (a module imported twice) is a no-op, another one a ValueError."""
    if not isinstance(spec.name, str) or not spec.name.isidentifier():
        raise ValueError(f"model name {spec.name!r} must be an identifier (letters, digits, _), e.g. 'my_fusion'")
    if not isinstance(spec.description, str) or not spec.description.strip():
        raise ValueError(f"model {spec.name!r}: its description must be a non-empty line for `emml models`")
    if not all(isinstance(k, str) for k in spec.switches):
        raise ValueError(f"model {spec.name!r}: its switches must be option names")
    _check_declared(spec.name, spec.fusion)
    old = _ENTRIES.get(spec.name)
    if old is not None:
        same = (old.fusion.__module__, old.fusion.__qualname__, old.architecture, dict(old.switches)) == (
            spec.fusion.__module__,
            spec.fusion.__qualname__,
            spec.architecture,
            dict(spec.switches),
        )
        if same:
            return old
        raise ValueError(f"model {spec.name!r} is already registered (by {old.source}); choose another name")
    _ENTRIES[spec.name] = spec
    plugins.count_registration()
    return spec


BUILD_ARGUMENTS = ("vocab_size", "height", "width", "max_steps")
"""What `emml.models.build_model` takes beside the options (by position, then the options by keyword): an option of
one of these names would reach it twice (a TypeError at the first training, its run dir already made)."""


def _check_declared(name: str, fusion: type[Fusion]) -> None:
    """A fusion's `Fusion.options` is a dataclass type whose fields have defaults and are not named as the options
    every model shares (`ModelConfig`); a ValueError names the model and the field."""
    declared = getattr(fusion, "options", None)
    if not (isinstance(declared, type) and is_dataclass(declared)):
        raise ValueError(
            f"model {name!r}: {fusion.__qualname__}.options={declared!r} must be a dataclass type (emml.models."
            "FusionOptions) whose fields are its options"
        )
    shared = option_fields(ModelConfig)
    for f in fields(declared):
        if f.name in shared or f.name in ("name", "options"):
            raise ValueError(
                f"model {name!r}: its option {f.name!r} is one every model shares (ModelConfig); name it otherwise"
            )
        if f.name in BUILD_ARGUMENTS:  # an option is passed to build_model by keyword beside these
            raise ValueError(
                f"model {name!r}: its option {f.name!r} is an argument of every model's build ("
                + ", ".join(BUILD_ARGUMENTS)
                + "); name it otherwise"
            )
    try:
        declared()
    except TypeError as e:
        raise ValueError(f"model {name!r}: every field of {declared.__qualname__} needs a default ({e})") from e


def register_model(
    name: str, description: str, fusion: type[Fusion] | None = None, **switches: Any
) -> ModelSpec | Callable[[F], F]:
    """Register fusion class `fusion` as architecture and model `name` (with `ModelConfig` `switches`); without
    `fusion`, a class decorator doing so. The class must subclass `Fusion`."""

    def add(cls: F) -> F:
        if not (isinstance(cls, type) and issubclass(cls, Fusion)):
            raise TypeError(f"model {name!r}: {cls!r} is not a subclass of emml.models.Fusion")
        _add(ModelSpec(name, description, name, cls, dict(switches), _source(cls.__module__)))
        return cls

    if fusion is None:
        return add
    add(fusion)
    return _ENTRIES[name]


def register_variant(name: str, of: str, description: str, **switches: Any) -> ModelSpec:
    """Register model `name`: registered model `of`'s architecture with `switches` on top of `of`'s (an ablation)."""
    base = _ENTRIES.get(of)
    if base is None:
        raise ValueError(f"model {name!r} is a variant of {of!r}, which is not registered")
    import sys

    source = _source(sys._getframe(1).f_globals.get("__name__", "?"))  # the module calling this function
    return _add(ModelSpec(name, description, base.architecture, base.fusion, {**base.switches, **switches}, source))


def _entries() -> dict[str, ModelSpec]:
    """Every entry, after loading the plugins (once per process; emml/models/plugins.py)."""
    plugins.load_plugins()
    return _ENTRIES


class _Models(Mapping):
    """`MODELS`: registry name -> `ModelSpec`, read live (a plugin's models appear once it is loaded)."""

    def __getitem__(self, name: str) -> ModelSpec:
        return _entries()[name]

    def __iter__(self) -> Iterator[str]:
        return iter(list(_entries()))

    def __len__(self) -> int:
        return len(_entries())

    def __repr__(self) -> str:
        return f"MODELS({', '.join(self)})"


class _Architectures(Sequence):
    """`ARCHITECTURES`: the names `ModelConfig.name` accepts, one per fusion class registered, read live."""

    def _names(self) -> list[str]:
        return [name for name, spec in _entries().items() if spec.architecture == name]

    def __getitem__(self, i):
        return self._names()[i]

    def __len__(self) -> int:
        return len(self._names())

    def __contains__(self, name) -> bool:
        spec = _entries().get(name) if isinstance(name, str) else None
        return spec is not None and spec.architecture == name

    def __repr__(self) -> str:
        return repr(tuple(self._names()))


MODELS: Mapping[str, ModelSpec] = _Models()
"""Every buildable model name -> its `ModelSpec` (plugins' included)."""
ARCHITECTURES: Sequence[str] = _Architectures()
"""Fusion architectures a `ModelConfig.name` may name (ablations are switches over one of them)."""


def architecture(name: str) -> type[Fusion]:
    """The fusion class of architecture `name` (a `ModelConfig.name`)."""
    if name not in ARCHITECTURES:
        raise ValueError(f"unknown fusion name={name!r}; known names: {', '.join(ARCHITECTURES)}; {PLUGIN_HINT}")
    return _ENTRIES[name].fusion


def fusion_options(model: str) -> type:
    """The options class (`Fusion.options`) of registry model ``model``'s fusion: the options a run of it may set
    beside the shared ones (`ModelConfig`); an unknown model fails naming it."""
    if model not in MODELS:
        raise ValueError(f"unknown model name={model!r}; known names: {', '.join(MODELS)}; {PLUGIN_HINT}")
    return MODELS[model].fusion.options


def check_architecture(cfg):
    """The registry's check of a `ModelConfig` (validated for its shared options' values): its name is a registered
    fusion, its ``options`` that fusion's declared options class (its defaults filled in where None) with values
    that pass their checks (`emml.config.schema.check_model_options`), the No Aux warm-up only for a fusion that
    keeps its answer off x_I (`Fusion.answer_warmup`), and the type_gate control meets a GA2 gate;
    returns ``cfg``."""
    fusion = architecture(cfg.name)
    declared = fusion.options
    if cfg.options is None:
        cfg.options = declared()
    if type(cfg.options) is not declared:
        raise ValueError(
            f"ModelConfig.options={cfg.options!r} must be the options of fusion {cfg.name!r}: a {declared.__qualname__}"
        )
    check_model_options(declared, {f.name: getattr(cfg.options, f.name) for f in fields(declared)})
    g = cfg.answer_gate_frames
    if g and not fusion.answer_warmup:
        raise ValueError(
            f"ModelConfig.answer_gate_frames={g!r} keeps the answer off the image encoder: model {cfg.name!r} "
            f"({fusion.__qualname__}) has no answer that reads x_I (Fusion.answer_warmup is False); allowed: 0"
        )
    if g and getattr(cfg.options, "answer_grad", "all") == "gate":
        raise ValueError(
            f"ModelConfig.answer_gate_frames={g!r} keeps the answer loss to the GA2 gate before switching to "
            "answer_grad: answer_grad='gate' keeps it there throughout (allowed with it: 0)"
        )
    if cfg.control == "type_gate" and not (issubclass(fusion, DualAttention) and cfg.options.ga2):
        raise ValueError(
            f"ModelConfig.control='type_gate' replaces the GA2 gate (Eq. 4): only for name='dual_attention' "
            f"with ga2=True (got name={cfg.name!r}, ga2={getattr(cfg.options, 'ga2', None)})"
        )
    return cfg


def build_fusion(cfg, vocab_size: int, height: int, width: int) -> Fusion:
    """Fusion unit of architecture `cfg.name` for a conv3 grid of (height, width) = (h, w)."""
    fusion = architecture(cfg.name).from_config(cfg, vocab_size, height, width)
    fusion.warm_up(cfg.answer_gate_frames)  # the No Aux warm-up, one rule for every fusion (`Fusion.at_frames`)
    dim = getattr(fusion, "state_dim", None)
    if isinstance(dim, bool) or not isinstance(dim, int) or dim < 1:
        raise ValueError(
            f"fusion {type(fusion).__qualname__} of model {cfg.name!r}: state_dim={dim!r} must be a positive integer "
            "(the size D of the x_S it returns, set in __init__)"
        )
    return fusion


# The paper's models (Chaplot et al. 2019): the appendix's baselines, PACMAN, Dual-Attention (§3.1, Eq. 1-5) and
# its ablations (§4, "Ablation tests"), in the order of `emml models`.
register_model("text_only", "Text only: x_S = [x_BoW, x_sent]", TextOnly)
register_model("image_only", "Image only: x_S = vec(x_I)", ImageOnly)
register_model("concat", "Concat: x_S = [vec(x_I), x_BoW, x_sent]", Concat)
register_model("ga", "Gated-Attention: x_S = vec(x_I ⊙ x_sent)", GatedAttention)
register_model("film", "FiLM: x_S = vec(gamma(x_sent) ⊙ x_I + beta(x_sent))", FiLM)
register_model("pacman", "PACMAN: QA attention over the last 5 frames", Pacman)
register_model("dual_attention", "Dual-Attention (proposed): GA1 -> SA -> GA2, {x_S}", DualAttention)
register_variant("da_no_sa", "dual_attention", "Dual-Attention w/o Spatial-Attention, {x_S}", spatial_attention=False)
register_variant("da_no_ga1", "dual_attention", "Dual-Attention w/o GA1 (no BoW gating), {x_S}", ga1=False)
register_variant("da_no_ga2", "dual_attention", "Dual-Attention w/o GA2 (no sentence gating), {x_S}", ga2=False)
register_variant("da_no_indicator", "dual_attention", "Dual-Attention w/o task indicator, {x_S}", task_indicator=False)
