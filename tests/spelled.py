"""Where a set of values is spelled out in emml's source: the guard of a concept with one home (the splits, the
tasks, a model option's choices). A collection literal (tuple, list, set) of strings holding every one of the values
is a second definition of the concept, which would drift from the first."""

from __future__ import annotations

import ast
from pathlib import Path

import emml

HOME = Path(emml.__file__).parent
"""The package read."""


def spelled(values, home: Path = HOME) -> list[str]:
    """'file:line: [literal]' for each tuple, list or set literal of strings in ``home``'s modules that holds every one
    of ``values``, in file and line order."""
    wanted = set(values)
    found = []
    for path in sorted(home.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if not isinstance(node, (ast.Tuple, ast.List, ast.Set)):
                continue
            strings = [e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)]
            if wanted <= set(strings):
                found.append(f"{path.relative_to(home.parent)}:{node.lineno}: {strings}")
    return found
