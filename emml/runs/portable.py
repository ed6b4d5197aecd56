"""What a param or tag of the store may hold: no folder of the machine that trained or imported a run. A path is
written relative to the checkout (`portable`), and a run's roots by their names in a checkout (`root_name`):
'/home/me/emml/runs' is ``runs`` in the store whichever machine trained it or imported its run dir."""

from __future__ import annotations

import os
import re
from pathlib import PurePosixPath

from emml.config.paths import checkout_root
from emml.runs.store import sqlite_path

_ABSOLUTE = re.compile(r"(?<![\w.:/~-])/[^\s'\",()\[\]{}]+")
"""An absolute POSIX path inside a value (a path alone, or in a tuple's repr): '/' not after a word, dot, colon
(a URI's 'sqlite:///x' is left alone) or another '/'."""
ROOTS = {"run_root": "runs", "results_root": "results"}
"""The config's roots (params of every run) and the checkout's folder each names by default."""
SCRATCH = "scratch"
"""The checkout's folder for what is not a result (emml.config.profiles.SCRATCH): smoke's roots are under it."""
OUTSIDE = " (outside the checkout)"
"""How a root that is no folder of a checkout is named: its folder's name and this."""


def portable(value: str) -> str:
    """``value`` with every absolute path in it written relative to the checkout (:func:`checkout_root`): what a
    param or tag may hold, so that the store names no folder of the machine that trained or imported (e.g.
    '/home/me/emml/runs' -> 'runs', '/tmp/x' -> '../../tmp/x' from /home/me/emml)."""
    if "/" not in value:
        return value
    root = str(checkout_root())

    def rel(m: re.Match) -> str:
        path = m.group(0)
        return os.path.relpath(path, root) if os.path.isabs(path) else path

    return _ABSOLUTE.sub(rel, value)


def root_name(value: str, default: str) -> str:
    """A run's root (``run_root``, ``results_root``) as the run's own name for it, the same on every machine: its
    path in the checkout ('/home/me/emml/runs/extended' -> ``runs/extended`` from /home/me/emml; 'runs' stays
    'runs'); a root outside this checkout (another machine's checkout, a pinned worktree's) from its last folder
    named ``default`` on, with the ``scratch/`` above it ('/work/main/runs' -> ``runs``, '/x/scratch/results' ->
    ``scratch/results``); else, never a path, its folder's name marked as outside (`OUTSIDE`)."""
    path = PurePosixPath(portable(str(value)))
    parts = path.parts
    if parts and ".." not in parts and not path.is_absolute():
        return str(path)
    if default in parts:
        at = len(parts) - 1 - parts[::-1].index(default)
        at -= at > 0 and parts[at - 1] == SCRATCH
        return str(PurePosixPath(*parts[at:]))
    return f"{path.name or value}{OUTSIDE}"


def portable_uri(uri: str) -> str:
    """A tracking URI as a report may print it: a sqlite store's file relative to the checkout
    ('sqlite:////home/me/emml/mlflow.db' -> 'sqlite:///mlflow.db'), any other URI as it is."""
    path = sqlite_path(uri)
    return f"sqlite:///{portable(str(path))}" if path is not None else uri
