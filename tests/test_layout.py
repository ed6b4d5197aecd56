"""The package's layout guards: no import circle among emml's modules and no module over `MAX_LINES` lines.

Circles are read from the source, not from a running interpreter: every ``import emml...`` and ``from emml...
import ...`` (relative ones too) at any depth counts, a function's own imports included. An import inside a function
hides a circle from Python's start-up but not from a reader: the two modules still need each other, and the next
module-level import of either closes it. ``from emml.x import y`` is an import of the module ``emml.x.y`` when there
is one, else of ``emml.x``. A circle is a strongly connected component of two modules or more (Tarjan); the message
names its modules, one path round it, and every import between its modules (file:line), the ones to move.
"""

from __future__ import annotations

import ast
from pathlib import Path

import emml

PACKAGE = Path(emml.__file__).parent
"""The package read by the guards."""
MAX_LINES = 500
"""The most lines a module of emml may have: a module this long has more than one job."""


def modules(package: Path) -> dict[str, Path]:
    """Every module under ``package`` by dotted name (a package by its own name, for its __init__.py)."""
    out = {}
    for path in sorted(package.rglob("*.py")):
        parts = [package.name, *path.relative_to(package).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def imports(name: str, path: Path, known: dict[str, Path]) -> list[tuple[str, int]]:
    """(module imported, line) for each import of a module of ``known`` in module ``name`` (file ``path``), at any
    depth; an import of a name that is not a module counts as one of the nearest module above it."""
    root = name.split(".")[0]
    here = name if path.name == "__init__.py" else name.rpartition(".")[0]  # the package a relative import starts at
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = here.split(".")[: len(here.split(".")) - (node.level - 1)]
                base = ".".join([*parent, *([base] if base else [])])
            targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names]
        else:
            continue
        for target in targets:
            if target.split(".")[0] != root:
                continue
            while target not in known and "." in target:
                target = target.rpartition(".")[0]
            if target in known and target != name:
                out.append((target, node.lineno))
    return out


def graph(known: dict[str, Path]) -> dict[str, dict[str, list[int]]]:
    """{module: {module it imports: [lines]}} over ``known``."""
    edges: dict[str, dict[str, list[int]]] = {name: {} for name in known}
    for name, path in known.items():
        for target, line in imports(name, path, known):
            edges[name].setdefault(target, []).append(line)
    return edges


def circles(edges: dict[str, dict[str, list[int]]]) -> list[list[str]]:
    """The strongly connected components of two modules or more (Tarjan's algorithm), each sorted, in name order."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in edges.get(node, {}):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(edges):
        if node not in index:
            visit(node)
    return sorted(found)


def cycle_path(edges: dict[str, dict[str, list[int]]], members: list[str]) -> list[str]:
    """The shortest path round a circle from its first module back to it (breadth first): every module on it is a
    member, as every module that leads back to the first is."""
    start = members[0]
    previous: dict[str, str] = {}
    frontier = [start]
    while frontier:
        following = []
        for node in frontier:
            for nxt in sorted(edges[node]):
                if nxt == start:
                    path = [node]
                    while path[-1] != start:
                        path.append(previous[path[-1]])
                    return [*reversed(path), start]
                if nxt not in previous:
                    previous[nxt] = node
                    following.append(nxt)
        frontier = following
    return members  # not reached: every member of a component lies on a path back to its first


def circle_reports(package: Path) -> dict[tuple[str, ...], str]:
    """Each import circle among ``package``'s modules (its modules, sorted) with its report: its modules, a path
    round it and each import that closes it (file:line)."""
    known = modules(package)
    edges = graph(known)
    out = {}
    for members in circles(edges):
        lines = [f"circle of {len(members)}: {', '.join(members)} ({' -> '.join(cycle_path(edges, members))})"]
        for source in members:
            for target, at in sorted(edges[source].items()):
                if target in members:
                    rel = known[source].relative_to(package.parent)
                    lines.append(f"  {source} imports {target} at {', '.join(f'{rel}:{n}' for n in sorted(set(at)))}")
        out[tuple(members)] = "\n".join(lines)
    return out


def circle_report(package: Path) -> str:
    """Every circle's report (`circle_reports`), one after another; "" when there is none."""
    return "\n".join(circle_reports(package).values())


def oversized(package: Path, limit: int = MAX_LINES) -> list[tuple[str, int]]:
    """(file, lines) of each module of ``package`` over ``limit`` lines, longest first."""
    counts = {
        str(path.relative_to(package.parent)): len(path.read_text(encoding="utf-8").splitlines())
        for path in modules(package).values()
    }
    return sorted(((f, n) for f, n in counts.items() if n > limit), key=lambda fn: (-fn[1], fn[0]))


def test_no_import_circle_among_emmls_modules():
    report = circle_report(PACKAGE)
    assert not report, f"import circles (function-local imports count; move the shared piece to its owner):\n{report}"


def test_no_module_of_emml_is_over_the_line_limit():
    found = oversized(PACKAGE)
    assert not found, f"modules over {MAX_LINES} lines (split each by job): " + ", ".join(
        f"{f} ({n} lines)" for f, n in found
    )


def test_the_layout_reads_the_real_package():
    """The guards read what they guard: the package's modules, and an import known to be there (a vacuous pass on
    an empty or misread package is a failure)."""
    known = modules(PACKAGE)
    assert len(known) > 100 and {"emml", "emml.runs.rundir", "emml.runs.segments"} <= set(known)
    assert "emml.runs.segments" in graph(known)["emml.runs.rundir"]


def plant(root: Path, files: dict[str, str]) -> Path:
    """A package ``emml`` under ``root`` with ``files`` ({path in it: source}); returns its folder."""
    package = root / "emml"
    for rel, source in {"__init__.py": "", **files}.items():
        path = package / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(source)
    return package


def test_a_planted_circle_through_a_function_local_import_is_named_with_its_lines(tmp_path):
    package = plant(
        tmp_path,
        {
            "a.py": "from emml.pkg import b\n",  # a module named by `from package import module`
            "pkg/__init__.py": "",
            "pkg/b.py": "import json\n\n\ndef f():\n    from emml.a import thing\n    return thing\n",
            "c.py": "import emml.a\n",  # reaches the circle, is not in it
        },
    )
    report = circle_report(package)
    assert "circle of 2: emml.a, emml.pkg.b (emml.a -> emml.pkg.b -> emml.a)" in report
    assert "emml.a imports emml.pkg.b at emml/a.py:1" in report
    assert "emml.pkg.b imports emml.a at emml/pkg/b.py:5" in report
    assert "emml.c" not in report
    (package / "pkg" / "b.py").write_text("import json\n")  # the circle broken
    assert circle_report(package) == ""


def test_every_circle_is_found_whatever_its_length_and_however_it_imports(tmp_path):
    """Three modules round one circle (a relative import among them, and a name that is not a module read as its
    module), two round another, and a chain that closes nothing."""
    package = plant(
        tmp_path,
        {
            "x.py": "from emml.y import helper\n",
            "y.py": "def helper():\n    from . import z\n",
            "z.py": "if True:\n    import emml.x as again\n",
            "p.py": "from emml import q\n",
            "q.py": "class Q:\n    def m(self):\n        from emml.p import P\n",
            "chain1.py": "import emml.chain2\n",
            "chain2.py": "import emml.chain3\n",
            "chain3.py": "import os\n",
            "self.py": "import emml.self\n",  # a module naming itself is no circle
        },
    )
    edges = graph(modules(package))
    assert circles(edges) == [["emml.p", "emml.q"], ["emml.x", "emml.y", "emml.z"]]
    assert edges["emml.self"] == {} and edges["emml.chain1"] == {"emml.chain2": [1]}
    assert cycle_path(edges, ["emml.x", "emml.y", "emml.z"]) == ["emml.x", "emml.y", "emml.z", "emml.x"]
    assert "emml.z imports emml.x at emml/z.py:2" in circle_report(package)


def test_a_module_over_the_limit_is_named_with_its_count(tmp_path):
    package = plant(tmp_path, {"long.py": "x = 1\n" * 501, "edge.py": "x = 1\n" * 500, "sub/__init__.py": "pass\n"})
    assert oversized(package) == [("emml/long.py", 501)]
    assert oversized(package, limit=499) == [("emml/long.py", 501), ("emml/edge.py", 500)]


def test_the_guards_fail_on_a_planted_circle_and_a_planted_long_module(tmp_path, monkeypatch):
    """The two guards themselves, pointed at a planted package: each fails, naming what it found."""
    import sys

    import pytest

    package = plant(tmp_path, {"a.py": "import emml.b\n", "b.py": "def f():\n    import emml.a\n" + "x = 1\n" * 499})
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", package)
    with pytest.raises(AssertionError, match=r"emml\.b imports emml\.a at emml/b\.py:2"):
        test_no_import_circle_among_emmls_modules()
    with pytest.raises(AssertionError, match=r"emml/b\.py \(501 lines\)"):
        test_no_module_of_emml_is_over_the_line_limit()
