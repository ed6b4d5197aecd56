"""A full disk in one line: the writes of a run (checkpoint, metrics mirror, results.json, results CSV) turn
ENOSPC (and a full quota) into :class:`NoSpaceError`, naming where, after removing their partial temp file."""

from __future__ import annotations

import errno
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

FULL = (errno.ENOSPC, errno.EDQUOT)
"""The errnos of a write refused for lack of room: no space left on the device, quota exceeded."""


class NoSpaceError(OSError):
    """A write failed for lack of disk space; the message names the folder and the file (one line)."""


RESUME = "free some space and rerun the same command to resume from the last checkpoint"
"""What a training does after a full disk (the default advice)."""
RERUN = "free some space and rerun the same command"
"""What any other writer (an import, reports, an exported mirror) does after a full disk."""


@contextmanager
def no_space_names(
    path: str | os.PathLike, tmp: str | os.PathLike | None = None, then: str | None = None
) -> Iterator[None]:
    """Inside the block, a full disk while writing ``path`` (through ``tmp``, removed then) raises NoSpaceError
    naming it and saying ``then`` (default `RESUME`); the file under ``path`` itself is left as it was (writes go
    through a temp file and a rename)."""
    try:
        yield
    except OSError as e:
        if isinstance(e, NoSpaceError) or e.errno not in FULL:
            raise
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        path = Path(path)
        raise NoSpaceError(
            f"no space left on {path.parent} (writing {path.name}, left as it was): {then or RESUME}"
        ) from None
