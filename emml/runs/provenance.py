"""A run's provenance as MLflow's UI reads it: ``mlflow.source.git.commit`` (and ``mlflow.source.name``) from the
run's ``git_sha`` tag (`source_tags`), and an experiment's description ``mlflow.note.content`` from its table's
caption (`experiment_note`)."""

from __future__ import annotations

import re
import subprocess
from collections.abc import Mapping
from typing import Any

from emml.config.paths import REPRODUCE_DIR, project_root

NOTE = "mlflow.note.content"
"""The description MLflow's UI shows for an experiment (or a run)."""
GIT_COMMIT = "mlflow.source.git.commit"
"""The commit MLflow's UI shows in a run's Source column (from the ``git_sha`` tag, :func:`source_tags`)."""

_COMMITS: dict[str, str] = {}


def full_commit(sha: str) -> str:
    """The full hash of commit ``sha`` (a run's short ``git_sha``) in the checkout's repository; ``sha`` itself when
    git does not know it (a run trained elsewhere, no git)."""
    if sha in _COMMITS:
        return _COMMITS[sha]
    full = sha
    if re.fullmatch(r"[0-9a-f]{4,40}", sha or ""):
        try:
            out = subprocess.run(
                ["git", "rev-parse", "--verify", "--quiet", f"{sha}^{{commit}}"],
                cwd=project_root(),
                capture_output=True,
                text=True,
                timeout=5,
            )
            full = out.stdout.strip() or sha
        except (OSError, subprocess.SubprocessError):
            pass
    _COMMITS[sha] = full
    return full


def source_tags(tags: Mapping[str, Any]) -> dict[str, str]:
    """The tags MLflow's UI reads for a run's Source, from the run's own ``git_sha`` tag (kept too): its commit (in
    full when this checkout's git knows it) and the program."""
    sha = str(tags.get("git_sha") or "")
    if not sha or sha == "unknown":
        return {}
    return {GIT_COMMIT: full_commit(sha), "mlflow.source.name": "emml", "mlflow.source.type": "LOCAL"}


def experiment_note(name: str) -> str:
    """An experiment's description (``mlflow.note.content``): the caption (``title``) of the table it holds the
    runs of, reproduce/<name>.toml or reproduce/experiments/<name>.toml, with the file; a name no file declares (a
    ``--set table=...`` of one's own) says so."""
    import tomllib

    for path in (REPRODUCE_DIR / f"{name}.toml", REPRODUCE_DIR / "experiments" / f"{name}.toml"):
        if path.is_file():
            try:
                data = tomllib.loads(path.read_text())
            except (OSError, tomllib.TOMLDecodeError):
                break
            title = str(data.get("title") or "").strip() or name
            ref = name if path.parent == REPRODUCE_DIR else f"experiments/{name}"
            return f"{title}\n\nThe runs of `{path.relative_to(REPRODUCE_DIR.parent)}` (`emml run {ref}`)."
    return f"Runs trained with table={name!r}; no table file of reproduce/ declares it."
