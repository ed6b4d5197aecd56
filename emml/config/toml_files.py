"""The one checker of the project's TOML files (reproduce/: the tables, the campaigns, the claims): a file format is
declared as pydantic models (`Section`: no key but its fields, each of its declared type, in strict mode), and
`check_file` holds a file's data to it before anything reads it. Every failure is one `FileError` in one dialect:
the file, the key path (``rows[0].more_seeds[1].seeds``) and what is wrong, with the allowed keys or values.

A field declares what it accepts on its annotation, as the configs do (emml/config/checks.py): a type, a `Literal` of
its choices, pydantic's constraints, and the words an error gives it (a string in `Annotated`: "a non-empty list of
booleans"). What needs more than the file (a model of the registry, a profile, another table's rows) is its loader's
to check, failing through `FileError` too. A leaf: it imports nothing of `emml` but emml.config.checks."""

from __future__ import annotations

import functools
import types
import typing
from pathlib import Path
from typing import Annotated, Literal

import pydantic
import tomllib
from pydantic import ConfigDict

from emml.config.checks import allowed as _words


class FileError(ValueError):
    """A file that breaks its format: ``<file>: key '<key path>': <what>``."""

    def __init__(self, path: Path | str, key: str, what: str):
        super().__init__(f"{path}: key {key!r}: {what}")
        self.path, self.key, self.what = path, key, what


class Section(pydantic.BaseModel):
    """A table of a file format: no key but its fields, each value of its declared type (no conversion: 1 is no
    string, "1" no number). Formats subclass it; a field's docstring says what the key means."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


def read_toml(path: Path) -> dict:
    """The data of TOML file ``path``; a syntax error names the file."""
    try:
        return tomllib.loads(Path(path).read_text())
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{path}: not valid TOML: {e}") from None


def check_file(path: Path | str, data: dict, form: type[Section]) -> Section:
    """``data`` (a file's) held to format ``form``: the checked model, or a `FileError` naming ``path``, the first
    offending key's path and what is wrong (an unknown key with the allowed keys, a missing one, a value not among
    the choices with them, a value of the wrong type with what the key accepts)."""
    try:
        return form.model_validate(data)
    except pydantic.ValidationError as e:
        first = min(e.errors(), key=lambda err: err["type"] != "extra_forbidden")  # an unknown key first: a typo
        key, what = explain(form, data, first)
        raise FileError(path, key, what) from None


def explain(form: type[Section], data, error: dict) -> tuple[str, str]:
    """(key path, what is wrong) for one pydantic error of ``data`` against ``form``. A list of plain values is named
    as a whole (``columns.aux``, not ``columns.aux[0]``): what it accepts is said of the list."""
    hint: object = form
    value = data
    parts: list[str] = []
    loc = list(error["loc"])
    for i, step in enumerate(loc):
        bare = _bare(hint)
        if _is_section(bare):
            parts.append(str(step))
            if step not in _hints(bare):  # a key the section does not declare
                return _path(parts), f"unknown key; allowed keys: {', '.join(_hints(bare))}"
            hint, value = _hints(bare)[step], value.get(step) if isinstance(value, dict) else None
        elif typing.get_origin(bare) is list and isinstance(step, int) and _is_section(_item(bare)):
            parts[-1] += f"[{step}]"
            hint, value = _item(bare), value[step]
        elif typing.get_origin(bare) is dict:
            parts.append(str(step))
            key_type, item_type = typing.get_args(bare)
            if loc[i + 1 : i + 2] == ["[key]"]:  # a key of a table whose keys are declared choices
                return _path(parts), f"unknown key; allowed keys: {', '.join(map(str, _choices(key_type)))}"
            hint, value = item_type, value.get(step) if isinstance(value, dict) else None
        else:  # an item of a list of plain values: said of the whole list
            break
    return _path(parts), _what(hint, value, error)


def _what(hint, value, error: dict) -> str:
    kind = error["type"]
    if kind == "missing":
        return "missing"
    if kind == "literal_error":
        return f"{error['input']!r} is not allowed; choose one of {', '.join(map(str, _choices(hint)))}"
    if kind == "value_error":  # a format's own validator: its message
        return str(error["ctx"]["error"])
    hint = _present(hint)
    return f"must be {'a table' if _is_section(_bare(hint)) else _words(hint)}, got {value!r}"


def _present(hint):
    """``hint`` without ``| None``: a key of a file is there with a value, or left out (TOML has no None)."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return hint


def _path(parts: list[str]) -> str:
    return ".".join(parts)


def _bare(hint):
    """``hint`` without `Annotated` and without ``| None`` (a key that may be left out)."""
    while True:
        origin = typing.get_origin(hint)
        if origin is Annotated:
            hint = typing.get_args(hint)[0]
        elif origin in (typing.Union, types.UnionType):
            args = [a for a in typing.get_args(hint) if a is not type(None)]
            if len(args) != 1:
                return hint
            hint = args[0]
        else:
            return hint


def _is_section(hint) -> bool:
    return isinstance(hint, type) and issubclass(hint, Section)


def _item(hint):
    return _bare(typing.get_args(_bare(hint))[0])


def _choices(hint) -> tuple:
    """The values of the `Literal` in ``hint`` (a list's or a dict's items included)."""
    hint = _bare(hint)
    if typing.get_origin(hint) is Literal:
        return typing.get_args(hint)
    for arg in typing.get_args(hint):
        found = _choices(arg)
        if found:
            return found
    return ()


@functools.cache
def _hints(section: type[Section]) -> dict:
    """A section's fields by name, with their declared annotations (the words an error gives them included)."""
    hints = typing.get_type_hints(section, include_extras=True)
    return {name: hints[name] for name in section.model_fields}
