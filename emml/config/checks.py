"""The value checks every config shares: each fails with a ValueError naming the field and what it accepts, before
any compute. A leaf: it imports nothing of `emml`."""

from __future__ import annotations

import re
from dataclasses import fields

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


def check_frames(name: str, value) -> None:
    """Raise a ValueError naming ``name`` unless ``value`` is a whole number of frames from 0 to MAX_FRAMES."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_FRAMES:
        raise ValueError(f"{name}={value!r} must be a whole number of frames from 0 to {MAX_FRAMES:,} (MAX_FRAMES)")


def check_at_least(config, names: tuple[str, ...], minimum: int) -> None:
    """Raise a ValueError naming the first of ``config``'s integer fields ``names`` below ``minimum`` (1: a positive
    integer, 0: >= 0)."""
    for name in names:
        value = getattr(config, name)
        if value < minimum:
            raise ValueError(f"{name}={value!r} must be " + ("a positive integer" if minimum == 1 else f">= {minimum}"))


def config_from_dict(cls, values: dict):
    """Build a config dataclass from a dict, rejecting unknown keys by name (tuples restored from lists)."""
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown {cls.__name__} field(s) {unknown}; known fields: {sorted(known)}")
    fixed = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    return cls(**fixed)
