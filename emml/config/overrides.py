"""`--set` overrides: fields set by dotted name on a `TrainConfig` (emml/config/schema.py), each value checked
against its field's type, naming where it came from (the --set option, or the profile)."""

from __future__ import annotations

from dataclasses import fields

from emml.config.env import match_env_class
from emml.config.model import SHARED_MODEL_OPTIONS


def apply_overrides(cfg, overrides: dict, source: str = "--set"):
    """Set ``cfg``'s fields (a `TrainConfig`) by dotted name ('frames', 'env.height', 'ppo.lr',
    'model_options.state_temperature'); an unknown name or a value of the wrong type fails naming ``source`` (the
    --set option, or the profile it came from), the field and what it accepts. A model option's name and value are
    checked against its model's declared options where the model registry is read (`emml.models.model_config`: where
    training starts, a table is read)."""
    for key, value in overrides.items():
        target, name = cfg, key
        if "." in key:
            section, name = key.split(".", 1)
            if section not in ("env", "ppo", "model_options"):
                raise ValueError(f"{source} {key!r}: section {section!r} is not one of 'env', 'ppo', 'model_options'")
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
            raise ValueError(f"{source} {key!r}: unknown field; known: {', '.join(known)}")
        setattr(target, name, _typed(value, getattr(target, name), f"{source} {key!r}"))
    cfg.env = match_env_class(cfg.env)
    cfg.env.aux_labels = cfg.aux
    return cfg


def _typed(value, current, where: str):
    """``value`` checked against the type of the field's current value (an int is accepted for a float)."""
    if current is None or isinstance(current, (tuple, list, dict)):
        return value
    if isinstance(current, bool):
        ok, what = type(value) is bool, "true or false"
    elif isinstance(current, int):
        ok, what = type(value) is int, "an integer"
    elif isinstance(current, float):
        ok, what = type(value) in (int, float), "a number"
        value = float(value) if ok else value
    elif isinstance(current, str):
        ok, what = isinstance(value, str), "a string"
    else:
        return value
    if not ok:
        raise ValueError(f"{where}: expected {what}, got {value!r}")
    return value
