"""Files the project reads back line by line: a run's metrics mirror (step,key,value) and the results CSVs.

Both are appended to or rewritten while other processes may be killed, so a file may end in a torn line: the
trace of a `kill -9` or a full disk in the middle of a write. That tail is cut back to the last whole record, with a
one-line note; anything else that is not a record is an error naming the file and the line (RecordError, a
ValueError: the CLI prints it in one line), never a parser's traceback (issue 54). Readers that only look
(`emml campaign --status`, reports) skip a torn tail without touching the file: a live run may be writing it.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

MIRROR_HEADER = "step,key,value"
"""The first line of every metrics mirror (emml.runs.tracking.Tracker.mirror_to)."""


class RecordError(ValueError):
    """A file the project reads back holds something that is not one of its records (the message names the file
    and the line)."""


def note(message: str) -> None:
    """A one-line note on stderr (what a reader did about a file, e.g. a torn tail cut back)."""
    print(f"note: {message}", file=sys.stderr, flush=True)


_SAID: set[str] = set()
"""The notes this process has said through `note_once`."""


def note_once(message: str, about: str | None = None) -> None:
    """`note`, unless this process said it already (about ``about``, default the message itself): a damaged file
    read by several readers (a table's curves, its efficiency section, the claims page; each step of `emml campaign
    --status`) is named once."""
    about = message if about is None else about
    if about not in _SAID:
        _SAID.add(about)
        note(message)


def torn_tail(data: bytes) -> int:
    """The length of ``data``'s whole lines: everything up to its last newline (all of it when it ends in one)."""
    return data.rfind(b"\n") + 1 if data and not data.endswith(b"\n") else len(data)


def cut_torn_tail(path: str | os.PathLike) -> str | None:
    """Truncate ``path`` to its last whole line when it ends in a torn one; returns the note said (None when the
    file was whole or is absent). A writer that appends (the trainer resuming a run onto its metrics mirror) calls
    it first, so that its first record does not land on the torn one (which would then be neither)."""
    path = Path(path)
    if not path.is_file():
        return None
    data = path.read_bytes()
    keep = torn_tail(data)
    if keep == len(data):
        return None
    with open(path, "r+b") as f:
        f.truncate(keep)
        f.flush()
        os.fsync(f.fileno())
    line = data[:keep].count(b"\n") + 1
    said = (
        f"{path}: line {line} was cut short ({len(data) - keep} bytes: a write interrupted by a kill or a full disk); "
        "cut back to the last whole record"
    )
    note(said)
    return said


def mirror_point(line: str) -> tuple[int, str, float] | None:
    """One line of a metrics mirror as (step, key, value); None when it is not one."""
    parts = line.split(",")
    if len(parts) != 3 or not parts[1]:
        return None
    try:
        step, value = int(parts[0]), float(parts[2])
    except ValueError:
        return None
    return (step, parts[1], value) if step >= 0 else None


def read_points(path: str | os.PathLike) -> list[tuple[int, str, float]]:
    """Every (step, key, value) of a metrics mirror, checked: a torn last line is left out (the file is not
    touched: a live run may be writing it), a header other than `MIRROR_HEADER` or any other line that is not a
    point is a RecordError naming the file and the line. [] for an absent or empty file."""
    path = Path(path)
    if not path.is_file():
        return []
    data = path.read_bytes()
    lines = data[: torn_tail(data)].decode("utf-8", errors="replace").split("\n")[:-1]
    if not lines:
        return []
    if lines[0] != MIRROR_HEADER:
        raise RecordError(f"{path}: line 1: expected the header {MIRROR_HEADER!r}, found {lines[0][:60]!r}")
    out = []
    for n, line in enumerate(lines[1:], 2):
        point = mirror_point(line)
        if point is None:
            raise RecordError(
                f"{path}: line {n}: not a metric point (step,key,value): {line[:60]!r}; delete that line (or the "
                "file: a run's curve is also in the MLflow store) to go on"
            )
        out.append(point)
    return out


def points_or_none(path: str | os.PathLike, left_out: str = "that run's curve and cells are left out") -> list | None:
    """`read_points` for a reader of many runs (reports, `emml campaign --status`): a damaged mirror costs its own run
    only. Its RecordError (the file and the line) is said once per process in a note ending in ``left_out``, and
    None is returned (the reader leaves that run's curve or cell out) where a whole file returns its points (issue
    65: one garbage line in one run skipped a whole table's page, or every report)."""
    try:
        return read_points(path)
    except RecordError as e:
        note_once(f"{e}; {left_out}", about=str(e))
        return None
