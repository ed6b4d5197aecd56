"""Where the project's folders are: the one owner of the checkout's root, under which run dirs (runs/), results
CSVs (results/), reports (reports/), scratch/ and the default MLflow store (mlflow.db) are written, and of the
reproduce/ folder the tables, profiles and campaigns are read from. Imports nothing of emml: any layer may call it."""

from __future__ import annotations

from pathlib import Path

REPRODUCE_DIR = Path(__file__).resolve().parents[2] / "reproduce"
"""reproduce/: profiles.toml, table*.toml, paper/table*.csv, experiments/ and campaigns/."""


def project_root() -> Path:
    """Directory holding ``pyproject.toml`` above this file (fallback: the cwd)."""
    for parent in Path(__file__).resolve().parents:
        if (parent / "pyproject.toml").is_file():
            return parent
    return Path.cwd()


def project_path(path: str | Path) -> Path:
    """``path`` as given when absolute, else under the project root (run and results roots are set this way)."""
    path = Path(path)
    return path if path.is_absolute() else project_root() / path
