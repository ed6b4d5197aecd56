"""How a model option is declared and checked: `model_option` declares one (a dataclass field of `ModelConfig`, the
options every model shares, or of a fusion's own options class, `emml.models.Fusion.options`), `check_model_options`
builds an options class from a run's values, each checked against its field's type and choices, naming the field.
A leaf: it imports nothing of `emml` but `emml.config.checks`."""

from __future__ import annotations

from dataclasses import Field, field, fields

from emml.config.checks import PLAIN_NAME, check, check_choice

NAME_PART = "name_part"
"""Key of a model option's field metadata (`model_option`): the format of its part of the run name."""
CHOICES = "choices"
"""Key of a model option's field metadata (`model_option`): its allowed values."""


def model_option(default, *, name: str | None = None, choices: tuple | None = None):
    """Declare a model option: a dataclass field of `ModelConfig` (the options every model shares) or of a fusion's
    own options class (`emml.models.Fusion.options`), its docstring below it as for every config field.

    ``default``: its value unless `TrainConfig.model_options` sets it (the paper's, for the paper's models).
    ``name``: the format of its part of the run name, spelled when a run sets it to another value than the default
    ('ans{}' with 'gate' gives 'ansgate'; a number formats as {:g}: 'xs{}' with 0.25 gives 'xs0.25'); None: a run that
    sets it is named by `emml.runs.naming.swept` ('+model_options.NAME=VALUE'), like any other field.
    ``choices``: its allowed values (checked by `check_model_options`, naming the field)."""
    metadata = {}
    if name is not None:
        if not isinstance(name, str) or name.count("{}") != 1 or not PLAIN_NAME.fullmatch(name.replace("{}", "x")):
            raise ValueError(f"model option name={name!r} must be a plain word holding '{{}}' once, e.g. 'ans{{}}'")
        metadata[NAME_PART] = name
    if choices is not None:
        metadata[CHOICES] = tuple(choices)
    return field(default=default, metadata=metadata)


def option_fields(options: type) -> dict[str, Field]:
    """A declared options class's fields (a dataclass type: `ModelConfig`'s shared ones, or a fusion's own), by name;
    the fields a class names in its `NOT_OPTIONS` (`ModelConfig`'s `name` and `options`) are not options a run sets."""
    skip = options.__dict__.get("NOT_OPTIONS", ())  # the class's own: a subclass declares its own
    return {f.name: f for f in fields(options) if f.name not in skip}


def check_model_options(options: type, values: dict, label: str = "ModelConfig"):
    """``options`` (a declared options class) built from ``values``: each value held to its field's type (`check`) and
    `model_option` choices, then the class's own ``check()`` (ranges, options that need one another); a ValueError
    names the field ('ModelConfig.eq1_words=...'). Unknown names are the caller's to refuse (`emml.models.model_config`
    names the model and its options)."""
    declared = option_fields(options)
    built = check(options(**values), f"{label}.", values)
    for name, value in values.items():
        allowed = declared[name].metadata.get(CHOICES)
        if allowed is not None:
            check_choice(f"{label}.{name}", value, allowed)
    if callable(getattr(built, "check", None)):
        built.check()
    return built
