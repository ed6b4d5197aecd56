"""Files written whole or not at all: the one writer of the project's text files and figures (results.json, a
results CSV, a metrics mirror exported from the store, every page, table, figure and the index `emml reports`
writes). Each goes to a temporary file in the same folder (a rename cannot cross file systems), then `os.replace`
puts it under its final name: a kill or a full disk in the middle leaves the old file (or none), never a partial
one under the final name (issue 65: a killed `emml reports` left a 0-byte figure linked from a whole-looking index).
A kill -9 can leave a hidden ``.<name>.*.tmp`` beside it, which no reader globs; the next write of the same file
removes those older than `STALE_TMP_S` (`sweep_stale`: a write takes milliseconds, so a temp file an hour old is no
live writer's). Checkpoints have their own writer (emml/runs/checkpoint.py: torch's, with an fsync of the folder)."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from emml.runs.diskspace import no_space_names

STALE_TMP_S = 3600
"""Age (seconds) past which a writer's temp file is what a kill left, not a write under way (a write takes
milliseconds): removed by the next write of the same file (`sweep_stale`)."""


@contextmanager
def replacing(path: str | os.PathLike, then: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` for the caller to write; when the block ends normally it replaces
    ``path`` (atomically), else it is removed and ``path`` left as it was. Its folder is created. A full disk is a
    NoSpaceError naming the folder and the file (`emml.runs.diskspace.no_space_names`; ``then``: what to do next)."""
    path = Path(path)
    with no_space_names(path, then=then):
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        os.fchmod(fd, _mode())  # mkstemp's 0600 would make every report readable by its writer only
        os.close(fd)
        tmp = Path(name)
        try:
            yield tmp
            os.replace(tmp, path)
        except BaseException:  # an error, Ctrl-C, SIGTERM (raised as an exception): the old file stays
            tmp.unlink(missing_ok=True)
            raise
    sweep_stale(path.parent, f".{path.name}.*.tmp")


def sweep_stale(folder: Path, pattern: str, max_age_s: float = STALE_TMP_S) -> list[Path]:
    """Remove the files of ``folder`` matching ``pattern`` (a writer's own temp names) last written more than
    ``max_age_s`` ago: what a kill -9 left mid-write. A file gone or unreadable meanwhile is left. Returns those
    removed."""
    import time

    now, removed = time.time(), []
    for tmp in folder.glob(pattern) if folder.is_dir() else ():
        try:
            if now - tmp.stat().st_mtime > max_age_s:
                tmp.unlink()
                removed.append(tmp)
        except OSError:
            continue
    return removed


def _mode() -> int:
    """The mode a plain ``open(path, 'w')`` gives a new file: 0666 less the process's umask."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def write_text(path: str | os.PathLike, text: str, then: str | None = None) -> Path:
    """``Path(path).write_text(text)``, whole or not at all (`replacing`). Returns the path."""
    with replacing(path, then) as tmp:
        tmp.write_text(text)
    return Path(path)
