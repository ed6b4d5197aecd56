"""The value checks every config shares: each fails with a ValueError naming the field and what it accepts, before
any compute. A config declares what each field accepts on its annotation (a type below, a `Literal` of its choices,
bool, int, float, str) and `check` holds the values to it with pydantic. A leaf: it imports nothing of `emml`."""

from __future__ import annotations

import contextlib
import functools
import re
import types
import typing
from dataclasses import fields
from typing import Annotated, Literal

import pydantic
from pydantic import Field

PLAIN_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
"""A table or profile name: it becomes a folder or file name, so no path separator, no leading dot."""


def check_choice(field: str, value, allowed) -> None:
    """Raise a ValueError naming the field and its allowed values."""
    if value not in allowed:
        raise ValueError(f"{field}={value!r} is not allowed; choose one of {', '.join(map(repr, allowed))}")


MAX_FRAMES = 10**10
"""The most frames any frame count may be (frames, eval_every, the No Aux warm-up): 200x the paper's longest
training (50M frames, Doom Hard) and about a month at the fastest rate measured here (4,314 frames/s, 8 stacked runs
on an H100, docs/throughput.md). A larger count is a typo (an extra zero, 1e20), and beyond 2^63 a step no longer
fits MLflow's metric steps (issue 65: 10^20 was accepted and its run named 'warm1e+20')."""

MAX_LR = 1.0
"""The largest learning rate accepted: 4,000x the paper's 2.5e-4 (Appendix A), already far past where Adam diverges
here; 1e308 passed and the run died after one update with a 127-line traceback (issue 85)."""
MAX_THREADS = 1024
"""The most torch threads a run may ask for (`threads`, `acting_threads`): more than any machine this runs on has
cores (16 on a GPU node, docs/throughput.md); a larger count is a typo."""
MAX_ENVS = 1024
"""The most parallel actors (`num_envs`): each is an engine process (~100 MB), 128x the paper's 8."""
MAX_EPISODES = 100_000
"""The most greedy episodes per (task, split) of an evaluation (`eval_episodes`, `final_eval_episodes`): 200x the
paper's 500; at ~0.1 s an episode, 100,000 are already ~11 h per (task, split)."""
MAX_EPOCHS = 100
"""The most PPO epochs per rollout (`ppo.epochs`): 25x the paper's 4."""

# What a field accepts, declared on its annotation: pydantic's constraints, and the words an error gives them.
Positive = Annotated[int, Field(ge=1), "a positive integer (>= 1)"]
Count = Annotated[int, Field(ge=0), ">= 0"]
Frames = Annotated[int, Field(ge=0, le=MAX_FRAMES), f"a whole number of frames from 0 to {MAX_FRAMES:,} (MAX_FRAMES)"]
PlainName = Annotated[
    str,
    Field(pattern=rf"^{PLAIN_NAME.pattern}$"),
    "a plain name: letters, digits, '_', '.' or '-', starting with a letter or digit (no path separators)",
]
Threads = Annotated[int, Field(ge=0, le=MAX_THREADS), f"an integer from 0 to {MAX_THREADS} (MAX_THREADS)"]
Envs = Annotated[int, Field(ge=1, le=MAX_ENVS), f"an integer from 1 to {MAX_ENVS} (MAX_ENVS)"]
Episodes = Annotated[int, Field(ge=1, le=MAX_EPISODES), f"an integer from 1 to {MAX_EPISODES:,} (MAX_EPISODES)"]
Epochs = Annotated[int, Field(ge=1, le=MAX_EPOCHS), f"an integer from 1 to {MAX_EPOCHS} (MAX_EPOCHS)"]
LearningRate = Annotated[
    float, Field(gt=0, le=MAX_LR, allow_inf_nan=False), f"a finite number > 0 and <= {MAX_LR:g} (MAX_LR)"
]
Folder = Annotated[
    str,
    Field(pattern=r"\S"),
    "a folder path, not empty (relative to the project root, or absolute)",
]
"""A run's root folder (`run_root`, `results_root`): an empty one wrote into the checkout's own ``adhoc/``."""
Words = Annotated[typing.Sequence[str], "a list of words"]
Sentences = Annotated[typing.Sequence[str], "a list of sentences"]
Fraction = Annotated[float, Field(ge=0, le=1), "a number in [0, 1]"]
PositiveNumber = Annotated[float, Field(gt=0, allow_inf_nan=False), "a finite number > 0"]
Weight = Annotated[float, Field(ge=0, allow_inf_nan=False), "a finite number >= 0"]

WORDS = {bool: "true or false", int: "an integer", float: "a number", str: "a string", type(None): "None"}
"""How an error names the values of a plain type (an int is a number too)."""


def allowed(hint) -> str:
    """What a declared type accepts, in words: a named type's own, a Literal's values, each type of a union."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is Annotated:
        said = [m for m in hint.__metadata__ if isinstance(m, str)]
        return said[-1] if said else allowed(args[0])
    if origin is Literal:
        return "one of " + ", ".join(map(repr, args))
    if origin in (typing.Union, types.UnionType):
        return " or ".join(map(allowed, args))
    return WORDS.get(hint, f"a {getattr(hint, '__name__', hint)}")


@functools.cache
def _declared(cls: type) -> dict:
    """``cls``'s fields by name: (annotation, its pydantic validator). None when an annotation does not resolve, no
    validator for a type pydantic does not know (a plugin's options: their own ``check()`` checks them)."""
    try:
        hints = typing.get_type_hints(cls, include_extras=True)
    except (NameError, TypeError):
        return {}
    declared = {}
    for f in fields(cls):
        with contextlib.suppress(pydantic.PydanticSchemaGenerationError):
            declared[f.name] = (hints[f.name], pydantic.TypeAdapter(hints[f.name]))
    return declared


def check(config, label: str = "", names=None):
    """``config`` (a config dataclass), each field's value (only ``names``' when given) held to its declared type by
    pydantic in strict mode: a value is neither converted (an int is a number) nor replaced. A ValueError names the
    first that is not, with its value and what the type accepts ('seed=-1 must be >= 0'; a Literal's choices as
    `check_choice` names them)."""
    for name, (hint, adapter) in _declared(type(config)).items():
        if names is not None and name not in names:
            continue
        value = getattr(config, name)
        try:
            adapter.validate_python(value, strict=True)
        except pydantic.ValidationError:
            if typing.get_origin(hint) is Literal:
                check_choice(label + name, value, typing.get_args(hint))
            raise ValueError(f"{label}{name}={value!r} must be {allowed(hint)}") from None
    return config


def config_from_dict(cls, values: dict):
    """Build a config dataclass from a dict, rejecting unknown keys by name (tuples restored from lists)."""
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown {cls.__name__} field(s) {unknown}; known fields: {sorted(known)}")
    fixed = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    return cls(**fixed)
