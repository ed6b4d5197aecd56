"""Where table files are and what they are called: the paper's tables (reproduce/tableN.toml), the experiments
beyond them (reproduce/experiments/<x>.toml, named ``experiments/<x>``) and a researcher's own .toml anywhere (named
by its stem). emml/experiments/tables.py reads what `find_table` finds."""

from __future__ import annotations

from pathlib import Path

from emml.config.paths import REPRODUCE_DIR


def table_path(name: str) -> Path:
    return REPRODUCE_DIR / f"{name}.toml"


def list_tables(directory: Path = REPRODUCE_DIR) -> list[str]:
    """Names of every table file in reproduce/ (table2, table3, …), sorted."""
    return sorted(p.stem for p in directory.glob("table*.toml"))


EXPERIMENTS_DIR = REPRODUCE_DIR / "experiments"
"""Tables beyond the paper's (reproduce/experiments/<name>.toml): a setting an issue measures, e.g. issue 34's x_sent
readout. A campaign step names one as ``experiments/<name>`` (emml/experiments/campaign/); `emml reports` reports
those with results."""


EXPERIMENT_PREFIX = "experiments/"
"""How an experiment table is named wherever a table name goes: `emml run experiments/eqa_gate`, a campaign step's
``table = "experiments/eqa_gate"`` (reproduce/experiments/eqa_gate.toml)."""


def list_experiments(directory: Path = EXPERIMENTS_DIR) -> list[str]:
    """Names of the experiment tables (reproduce/experiments/*.toml), sorted."""
    return sorted(p.stem for p in directory.glob("*.toml"))


def table_names() -> list[str]:
    """Every name `load_table` takes for a table of reproduce/: table2..5, then experiments/<name>."""
    return [*list_tables(), *(EXPERIMENT_PREFIX + e for e in list_experiments())]


def experiment_file(name: str) -> Path:
    """reproduce/experiments/<x>.toml for ``name = "experiments/<x>"``; an unknown one fails naming those there are."""
    file = EXPERIMENTS_DIR / f"{name.removeprefix(EXPERIMENT_PREFIX)}.toml"
    if not file.is_file():
        known = ", ".join(repr(EXPERIMENT_PREFIX + e) for e in list_experiments())
        raise ValueError(f"table={name!r} is unknown; the experiments are {known}")
    return file


def table_ref(path: Path) -> str:
    """A table file as a user types it, the inverse of `experiment_file`: ``experiments/<name>`` for
    reproduce/experiments/<name>.toml, else relative to the project root when under it."""
    path = path.resolve()
    if path.parent == EXPERIMENTS_DIR:
        return EXPERIMENT_PREFIX + path.stem
    try:
        return str(path.relative_to(REPRODUCE_DIR.parent))
    except ValueError:
        return str(path)


OWN_TABLES: dict[str, Path] = {}
"""Tables of one's own loaded from a .toml path in this process (`load_table('./my_table.toml')`): name (the file's
stem) -> file, so that loading them again by name (the launcher, reports) finds them."""


def own_table(path: str | Path) -> str:
    """The name of the table file at `path` (a researcher's own .toml, anywhere), remembered in `OWN_TABLES`."""
    file = Path(path).expanduser().resolve()
    if not file.is_file():
        raise ValueError(f"table file {path}: no such file")
    if file.suffix != ".toml":
        raise ValueError(f"table file {path}: a table file ends in .toml")
    if file.stem in list_tables() and file != table_path(file.stem).resolve():
        raise ValueError(f"table file {path}: {file.stem!r} is a table of reproduce/; rename the file")
    OWN_TABLES[file.stem] = file
    return file.stem


def find_table(name: str) -> tuple[str, Path]:
    """The name a table goes by and its file, for every name `load_table` takes: a table of reproduce/ (``table2``),
    an experiment (``experiments/<x>``: named ``<x>``), the path of a .toml of one's own (named by its stem), or a
    name loaded from such a path before in this process (`OWN_TABLES`). An unknown name fails naming those there are."""
    if name.startswith(EXPERIMENT_PREFIX):
        name = own_table(experiment_file(name))
    elif name.endswith(".toml"):
        name = own_table(name)
    path = OWN_TABLES.get(name) or table_path(name)
    if not path.exists():
        raise ValueError(f"table={name!r} is unknown; choose one of {', '.join(map(repr, table_names()))}")
    return name, path
