"""What a param or tag of the store may hold: no folder of the machine that trained or imported a run. A run's roots
are written by their names in a checkout (`root_name`): '/home/me/emml/runs' is ``runs`` in the store whichever
machine trained it or imported its run dir; a path under a root from the root's name on, any other path relative
to the checkout, and one outside it as a root outside is named (`named`): never '..', never a folder of the
machine. `portable` (relative to the checkout, '..' allowed) is for what a page or the terminal prints."""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from pathlib import PurePosixPath

from emml.config.paths import checkout_root, project_path
from emml.runs.store import sqlite_path

_ABSOLUTE = re.compile(r"(?<![\w.:/~)-])/[^\s'\",()\[\]{}]+")
"""An absolute POSIX path inside a value (a path alone, or in a tuple's repr): '/' not after a word, dot, colon
(a URI's 'sqlite:///x' is left alone), another '/' or a ')' (a path from a root outside the checkout, `named`:
'ext (outside the checkout)/table2/r')."""
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
    return _from_root(parts, (default,)) or f"{path.name or value}{OUTSIDE}"


def _from_root(parts: tuple[str, ...], defaults) -> str | None:
    """The path of ``parts`` from its last folder named one of ``defaults`` on (with the ``scratch/`` above it), None
    when it has none."""
    at = max((i for i, p in enumerate(parts) if p in defaults), default=None)
    if at is None:
        return None
    at -= at > 0 and parts[at - 1] == SCRATCH
    return str(PurePosixPath(*parts[at:]))


def run_roots(params: Mapping) -> dict[str, str]:
    """The roots a run's config names (``run_root``, ``results_root``, as given: relative to the checkout or
    absolute) as (absolute folder -> its name in the store, `root_name`): what `named` names the paths under them
    by."""
    return {
        os.path.normpath(project_path(str(params[k]))): root_name(str(params[k]), default)
        for k, default in ROOTS.items()
        if params.get(k) not in (None, "")
    }


def named(value: str, roots: Mapping[str, str] | None = None) -> str:
    """``value`` as a param or tag of the store holds it, the same whichever machine or folder the run was trained
    or imported in: every absolute path in it written from the name of the deepest of ``roots`` (`run_roots`) it is
    under ('/tmp/ext/table2/r/checkpoint.pt' under the run root /tmp/ext: 'ext (outside the checkout)/table2/r/
    checkpoint.pt', as the ``run_root`` param reads 'ext (outside the checkout)'); else relative to the checkout when
    in it; else from its last folder named runs/ or results/ on (another machine's checkout), else its name marked
    as outside (`OUTSIDE`). Never '..', never a folder of this machine."""
    if "/" not in value:
        return value
    ordered = sorted((roots or {}).items(), key=lambda item: -len(item[0]))
    top = str(checkout_root())

    def name(m: re.Match) -> str:
        path = os.path.normpath(m.group(0))
        for root, root_as in ordered:
            if path == root or path.startswith(root.rstrip("/") + "/"):
                rest = os.path.relpath(path, root)
                return root_as if rest == "." else f"{root_as}/{rest}"
        rel = os.path.relpath(path, top)
        if rel != ".." and not rel.startswith("../"):
            return rel
        parts = PurePosixPath(path).parts
        return _from_root(parts, tuple(ROOTS.values())) or f"{parts[-1] if len(parts) > 1 else path}{OUTSIDE}"

    return _ABSOLUTE.sub(name, value)


def portable_uri(uri: str) -> str:
    """A tracking URI as a report may print it: a sqlite store's file relative to the checkout
    ('sqlite:////home/me/emml/mlflow.db' -> 'sqlite:///mlflow.db'), any other URI as it is."""
    path = sqlite_path(uri)
    return f"sqlite:///{portable(str(path))}" if path is not None else uri
