"""`--set` overrides: fields set by dotted name on a `TrainConfig` (emml/config/schema.py), each value checked
against its field's type, naming where it came from (the --set option, or the profile)."""

from __future__ import annotations

from dataclasses import fields

import pydantic

from emml.config.checks import WORDS
from emml.config.env import match_env_class
from emml.config.model import SHARED_MODEL_OPTIONS


def apply_overrides(cfg, overrides: dict, source: str = "--set"):
    """Set ``cfg``'s fields (a `TrainConfig`) by dotted name ('frames', 'env.height', 'ppo.lr',
    'model_options.state_temperature'); an unknown name or a value of the wrong type fails naming ``source`` (the
    --set option, or the profile it came from), the field and what it accepts. A model option's name and value are
    checked against its model's declared options where the model registry is read (`emml.models.model_config`: where
    training starts, a table is read). An unknown name is also answered with the dotted names whose last part is
    closest to its own (difflib), in any section: 'fraems' -> 'frames', 'env.heigth' -> 'env.height', 'lr' ->
    'ppo.lr'."""

    def did_you_mean(key: str) -> str:
        import difflib

        names = [f.name for f in fields(cfg)]
        names += [f"{s}.{f.name}" for s in ("env", "ppo") for f in fields(getattr(cfg, s))]
        leaf = {n: n.rsplit(".", 1)[-1] for n in names}
        near = difflib.get_close_matches(key.rsplit(".", 1)[-1], set(leaf.values()), n=3)
        close = [n for word in near for n in names if leaf[n] == word and n != key]
        return f"; did you mean {' or '.join(map(repr, close[:3]))}?" if close else ""

    for key, value in overrides.items():
        target, name = cfg, key
        if "." in key:
            section, name = key.split(".", 1)
            if section not in ("env", "ppo", "model_options"):
                raise ValueError(
                    f"{source} {key!r}: section {section!r} is not one of 'env', 'ppo', 'model_options'"
                    + did_you_mean(key)
                )
            if section == "model_options":  # its name and value: the model registry's check (`validate`)
                if not name.isidentifier() or name in ("name", "options"):
                    raise ValueError(
                        f"{source} {key!r}: not a model option name; the options every model shares: "
                        + ", ".join(SHARED_MODEL_OPTIONS)
                        + " (and its fusion's own, `emml models`)"
                    )
                cfg.model_options = {**cfg.model_options, name: value}
                continue
            target = getattr(cfg, section)
        known = [f.name for f in fields(target)]
        if name not in known:
            raise ValueError(f"{source} {key!r}: unknown field; known: {', '.join(known)}{did_you_mean(key)}")
        setattr(target, name, _typed(value, getattr(target, name), f"{source} {key!r}"))
    cfg.env = match_env_class(cfg.env)
    cfg.env.aux_labels = cfg.aux
    return cfg


_PLAIN = {kind: pydantic.TypeAdapter(kind) for kind in (bool, int, float, str)}
"""pydantic's validators of the types a value set by name is held to (its field's current value's)."""


def _typed(value, current, where: str):
    """``value`` held to the type of the field's current value by pydantic in strict mode (an int is accepted for a
    float, and made one); a None, list, table or config is left to `validate`."""
    if type(current) not in _PLAIN:
        return value
    try:
        return _PLAIN[type(current)].validate_python(value, strict=True)
    except pydantic.ValidationError:
        raise ValueError(f"{where}: expected {WORDS[type(current)]}, got {value!r}") from None
