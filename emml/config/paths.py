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


PLUGINS_ENV_VAR = "EMML_PLUGINS"
"""The plugins of this process and its children: paths or dotted modules, os.pathsep between them (read here, where
nothing heavy is imported, so that the CLI checks for plugins without loading the model zoo and torch)."""
PIN_DIR = ".campaign"
"""Under a checkout (git-ignored): the git worktrees campaigns run from, one per commit (`<checkout>/.campaign/<sha>/`,
emml.experiments.campaign.pin_worktree), and the lock that lets one campaign run per checkout."""


def checkout_root() -> Path:
    """The checkout whose folders (runs/, results/, scratch/, reports/) are written: the project root, or, for a
    campaign's pinned worktree (`<checkout>/.campaign/<sha>/`), the checkout it was made from. A pinned campaign
    runs the worktree's code but writes the checkout's files; a smoke step resolved under the worktree would slip
    past the guard that keeps smoke numbers out of the checkout's committed results/ (issue 54)."""
    root = project_root()
    if root.parent.name == PIN_DIR and (root.parent.parent / "pyproject.toml").is_file():
        return root.parent.parent
    return root


def project_path(path: str | Path) -> Path:
    """``path`` as given when absolute, else under the checkout (`checkout_root`: run and results roots are set this
    way)."""
    path = Path(path)
    return path if path.is_absolute() else checkout_root() / path
