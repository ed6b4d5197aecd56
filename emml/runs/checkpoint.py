"""Crash-safe checkpoints and RNG-state capture.

:func:`save_checkpoint` never leaves a half-written file under the final name:
it writes to a temporary file in the *same* directory (so the rename cannot
cross filesystems), flushes and fsyncs it, then ``os.replace``-s it over the
target (atomic on POSIX and Windows) and fsyncs the directory. A crash at any
point leaves either the previous checkpoint or the new one, plus at worst a
stray ``.<name>.*.tmp`` file that loaders ignore.
"""

from __future__ import annotations

import os
import random
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import torch

from emml.runs.diskspace import no_space_names


def save_checkpoint(path: str | os.PathLike, payload: dict[str, Any]) -> Path:
    """Atomically write ``payload`` (anything ``torch.save`` accepts) to ``path``.

    Parent directories are created. Returns the final path.
    """
    path = Path(path)
    with no_space_names(path):  # a full disk: one line naming the path; the last good checkpoint stays
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh:
                sink = _Sink(fh)
                try:
                    torch.save(payload, sink)
                except RuntimeError:  # torch's writer wraps the OSError of a full disk: the cause, unwrapped
                    if sink.error is not None:
                        raise sink.error from None
                    raise
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp_name, path)
        except BaseException:
            # Orderly failure (exception, Ctrl-C): remove our temp file. A hard kill
            # skips this and leaves the temp file, which is harmless.
            try:
                os.unlink(tmp_name)
            except FileNotFoundError:
                pass
            raise
    _fsync_dir(path.parent)
    return path


class _Sink:
    """The file torch.save writes to, remembering the OSError of a failed write: torch's zip writer turns it into a
    RuntimeError ("file write failed") that hides the cause, so a full disk read as a traceback instead of the one
    line `no_space_names` says (issue 54)."""

    def __init__(self, fh):
        self._fh, self.error = fh, None

    def write(self, data) -> int:
        try:
            return self._fh.write(data)
        except OSError as e:
            self.error = e
            raise

    def flush(self) -> None:
        self._fh.flush()


def _fsync_dir(directory: Path) -> None:
    """Persist the rename itself (best effort; not supported on every platform)."""
    try:
        dir_fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dir_fd)
    except OSError:
        pass
    finally:
        os.close(dir_fd)


class CheckpointError(ValueError):
    """A path that does not hold a readable emml checkpoint (the message names the path and what is wrong)."""


REQUIRED_KEYS = ("model", "config", "frames")


def load_checkpoint(
    path: str | os.PathLike, map_location: str | torch.device = "cpu", require: tuple[str, ...] = REQUIRED_KEYS
) -> dict[str, Any]:
    """Load a checkpoint written by :func:`save_checkpoint`; CheckpointError if ``path`` is not one (a missing
    file, a directory, an empty or unreadable file, or a payload without the ``require``-d keys).

    Uses ``weights_only=False`` because payloads carry RNG states (numpy
    tuples, python ``random`` state) -- only load checkpoints you wrote.
    """
    path = Path(path)
    if not path.exists():
        raise CheckpointError(f"checkpoint {path}: no such file")
    if path.is_dir():
        hint = " (did you mean its checkpoint.pt?)" if (path / "checkpoint.pt").exists() else ""
        raise CheckpointError(f"checkpoint {path}: is a directory, not a checkpoint file{hint}")
    if path.stat().st_size == 0:
        raise CheckpointError(
            f"checkpoint {path}: is empty (0 bytes); emml writes checkpoints atomically, so "
            "this file is not one of its checkpoints"
        )
    try:
        payload = torch.load(path, map_location=map_location, weights_only=False)
    except Exception as e:  # torch.load raises pickle, zip and EOF errors of many types
        raise CheckpointError(f"checkpoint {path}: not a PyTorch checkpoint ({type(e).__name__}: {e})") from None
    missing = [k for k in require if not isinstance(payload, dict) or k not in payload]
    if missing:
        raise CheckpointError(f"checkpoint {path}: not an emml checkpoint (missing {', '.join(missing)})")
    return payload


def rng_state() -> dict[str, Any]:
    """Capture python ``random``, numpy global and torch (CPU and, if present, CUDA) RNG states."""
    state: dict[str, Any] = {
        "python": random.getstate(),
        "numpy": np.random.get_state(),
        "torch": torch.get_rng_state(),
    }
    if torch.cuda.is_available():
        state["torch_cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict[str, Any]) -> None:
    """Restore the states captured by :func:`rng_state`."""
    random.setstate(state["python"])
    np.random.set_state(state["numpy"])
    torch.set_rng_state(state["torch"].cpu())
    if "torch_cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all([s.cpu() for s in state["torch_cuda"]])
