"""Plugins: models of one's own, registered from outside the package (docs/own-model.md, "Compare your own model").

A plugin is a module that registers models when imported (`emml.models.register_model`). It is found in two ways:

* the entry-point group ``emml.models`` of an installed distribution, e.g. in its pyproject.toml
  ``[project.entry-points."emml.models"] my_fusion = "my_package.fusion"``;
* a path to a .py file or a package folder, or a dotted module importable from sys.path, named by
  ``emml --plugin PATH_OR_MODULE`` (repeatable) or by the ``EMML_PLUGINS`` environment variable (os.pathsep
  between plugins). The option adds to the variable, so every process the command starts (a table's runs,
  Slurm jobs) loads the same plugins.

Loading is lazy and idempotent: the model registry loads the plugins the first time it is read (emml/models/
registry.py), and again only those added since; each plugin is imported once per process. A plugin that fails
raises one `PluginError` naming it and the cause. Imports nothing of emml (the registry tells it of each model
it adds: `count_registration`), so that the registry may load it and any layer may call it.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import re
import sys
import zlib
from pathlib import Path

from emml.config.paths import PLUGINS_ENV_VAR

ENV_VAR = PLUGINS_ENV_VAR
"""The plugins of this process and its children (emml/config/paths.py `PLUGINS_ENV_VAR`)."""
ENTRY_POINT_GROUP = "emml.models"
"""The entry-point group installed distributions declare their model modules in."""

_loaded: set[str] = set()
"""The plugins imported in this process (`key`), entry points as 'entry point NAME'."""
_entry_points_done = False
_loading = False
"""True while plugins load: a plugin that reads the registry while it registers must not load them again."""
_registrations = 0
"""Models added to the registry in this process (`count_registration`)."""


class PluginError(ValueError):
    """A plugin that cannot be found or imported, or that registers nothing; the message names it and the cause."""


def configured() -> list[str]:
    """The plugins `EMML_PLUGINS` names, in order, without duplicates."""
    out: list[str] = []
    for item in os.environ.get(ENV_VAR, "").split(os.pathsep):
        item = item.strip()
        if item and item not in out:
            out.append(item)
    return out


def is_path(spec: str) -> bool:
    """Whether `spec` names a file or folder (rather than a dotted module): it ends in .py, holds a path separator,
    or exists."""
    return spec.endswith(".py") or os.sep in spec or "/" in spec or Path(spec).exists()


def key(spec: str) -> str:
    """The form of `spec` `EMML_PLUGINS` keeps: a path made absolute (a child process may run elsewhere), a dotted
    module as given."""
    return str(Path(spec).expanduser().resolve()) if is_path(spec) else spec


def add_plugins(specs: list[str]) -> None:
    """Add `specs` (paths or dotted modules) to `EMML_PLUGINS`, for this process and the ones it starts, and load
    every plugin (`load_plugins`). A plugin that fails raises `PluginError`."""
    names = configured()
    for spec in specs:
        if key(spec) not in names:
            names.append(key(spec))
    if names:
        os.environ[ENV_VAR] = os.pathsep.join(names)
    load_plugins()


def load_plugins() -> None:
    """Import every plugin not imported yet in this process: the ``emml.models`` entry points (once), then
    `EMML_PLUGINS` in order. Cheap when nothing is new."""
    global _entry_points_done, _loading
    if _loading:
        return
    _loading = True
    try:
        if not _entry_points_done:
            _entry_points_done = True
            _load_entry_points()
        for spec in configured():
            if spec not in _loaded:
                _load(spec)
                _loaded.add(spec)
    finally:
        _loading = False


def _load_entry_points() -> None:
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINT_GROUP):
        what = f"entry point {ep.name} = {ep.value!r} (group {ENTRY_POINT_GROUP})"
        if what in _loaded:
            continue
        try:
            ep.load()  # imports the module, which registers its models
        except Exception as e:  # noqa: BLE001 - any failure of a plugin is reported as one line naming it
            raise PluginError(f"plugin {what} failed to load: {type(e).__name__}: {e}") from e
        _loaded.add(what)


def count_registration() -> None:
    """Called by the model registry for each model it adds (emml/models/registry.py, `_add`), so that a plugin
    that registers none is named without this module reading the registry."""
    global _registrations
    _registrations += 1


def _registered() -> int:
    return _registrations


def _load(spec: str) -> None:
    """Import plugin `spec` (a path to a .py file or a package folder, or a dotted module)."""
    before = _registered()
    if is_path(spec):
        path = Path(spec)
        if not path.exists():
            raise PluginError(f"plugin {spec!r}: no such file or folder")
        init = path / "__init__.py" if path.is_dir() else path
        if path.is_dir() and not init.exists():
            raise PluginError(f"plugin {spec!r}: a folder plugin must be a package (it has no __init__.py)")
        if init.suffix != ".py":
            raise PluginError(f"plugin {spec!r}: not a Python file (.py) or package folder")
        name = _module_name(path)
        fresh = name not in sys.modules
        if fresh:
            found = importlib.util.spec_from_file_location(
                name, init, submodule_search_locations=[str(path)] if path.is_dir() else None
            )
            module = importlib.util.module_from_spec(found)
            sys.modules[name] = module  # before running it: dataclasses and relative imports look it up there
            try:
                found.loader.exec_module(module)
            except BaseException as e:
                del sys.modules[name]
                if not isinstance(e, Exception):
                    raise
                raise PluginError(f"plugin {spec!r} failed while importing: {type(e).__name__}: {e}") from e
    else:
        fresh = spec not in sys.modules
        try:
            importlib.import_module(spec)
        except ModuleNotFoundError as e:
            if e.name and spec.startswith(e.name):
                raise PluginError(
                    f"plugin {spec!r}: no module named {e.name!r} (give a path to a .py file, or a module "
                    "importable from sys.path)"
                ) from e
            raise PluginError(f"plugin {spec!r} failed while importing: {type(e).__name__}: {e}") from e
        except Exception as e:  # noqa: BLE001 - any failure of a plugin is reported as one line naming it
            raise PluginError(f"plugin {spec!r} failed while importing: {type(e).__name__}: {e}") from e
    if fresh and _registered() == before:
        raise PluginError(
            f"plugin {spec!r} registered no model: decorate its fusion class with "
            "@emml.models.register_model(NAME, DESCRIPTION)"
        )


def _module_name(path: Path) -> str:
    """'emml_plugin_<stem>' for a plugin file or folder, made unique per path."""
    stem = re.sub(r"\W", "_", path.stem if path.is_file() else path.name)
    name = f"emml_plugin_{stem}"
    module = sys.modules.get(name)
    if module is not None and Path(getattr(module, "__file__", "") or "").resolve() not in (
        path.resolve(),
        (path / "__init__.py").resolve(),
    ):
        name = f"{name}_{zlib.crc32(str(path.resolve()).encode()):08x}"
    return name
