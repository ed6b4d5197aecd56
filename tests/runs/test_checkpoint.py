"""Atomic checkpoints and RNG round-trips."""

import os
import random
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from emml.runs import checkpoint
from emml.runs.checkpoint import load_checkpoint, rng_state, save_checkpoint, set_rng_state

ROOT = Path(__file__).resolve().parents[2]


def test_roundtrip_and_creates_parent(tmp_path):
    path = tmp_path / "deep" / "dir" / "ckpt.pt"
    payload = {"model": {"w": torch.arange(6.0).view(2, 3)}, "step": 7, "rng": rng_state()}
    save_checkpoint(path, payload)
    out = load_checkpoint(path, require=())
    assert out["step"] == 7 and torch.equal(out["model"]["w"], payload["model"]["w"])
    assert [p.name for p in path.parent.iterdir()] == ["ckpt.pt"]  # no temp files left


def test_hard_crash_before_replace_keeps_original(tmp_path):
    """A process killed between writing the temp file and renaming it leaves the old checkpoint intact."""
    path = tmp_path / "ckpt.pt"
    save_checkpoint(path, {"step": 1})
    script = textwrap.dedent(
        f"""
        import os, torch
        from emml.runs.checkpoint import save_checkpoint
        os.replace = lambda *a, **k: os._exit(9)  # die like SIGKILL right before the rename
        save_checkpoint({str(path)!r}, {{"step": 2, "big": torch.zeros(1000)}})
        """
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True)
    assert proc.returncode == 9, proc.stderr.decode()
    leftovers = [p for p in tmp_path.iterdir() if p.name != "ckpt.pt"]
    assert len(leftovers) == 1 and leftovers[0].name.endswith(".tmp")  # temp file left behind
    assert load_checkpoint(path, require=())["step"] == 1  # original intact
    assert torch.load(leftovers[0], weights_only=False)["step"] == 2  # (it was fully written)
    save_checkpoint(path, {"step": 3})  # a later save still works
    assert load_checkpoint(path, require=())["step"] == 3


def test_exception_during_write_cleans_up(tmp_path, monkeypatch):
    path = tmp_path / "ckpt.pt"
    save_checkpoint(path, {"step": 1})

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(checkpoint.torch, "save", boom)
    with pytest.raises(OSError):
        save_checkpoint(path, {"step": 2})
    monkeypatch.undo()
    assert [p.name for p in tmp_path.iterdir()] == ["ckpt.pt"]
    assert load_checkpoint(path, require=())["step"] == 1


def test_rng_state_roundtrip(tmp_path):
    random.seed(1), np.random.seed(1), torch.manual_seed(1)
    save_checkpoint(tmp_path / "r.pt", {"rng": rng_state()})
    a = (random.random(), np.random.rand(), torch.rand(1).item())
    random.seed(99), np.random.seed(99), torch.manual_seed(99)
    set_rng_state(load_checkpoint(tmp_path / "r.pt", require=())["rng"])
    assert (random.random(), np.random.rand(), torch.rand(1).item()) == a


def test_a_full_disk_is_one_line_naming_the_path_and_keeps_the_last_checkpoint(tmp_path, monkeypatch):
    import errno

    from emml.runs.diskspace import NoSpaceError

    path = tmp_path / "ckpt.pt"
    save_checkpoint(path, {"step": 1})

    def fills_the_disk(payload, fh):
        fh.write(b"half a checkpoint")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(checkpoint.torch, "save", fills_the_disk)
    with pytest.raises(NoSpaceError) as e:
        save_checkpoint(path, {"step": 2})
    assert str(e.value).startswith(f"no space left on {tmp_path} (writing ckpt.pt, left as it was): free some space")
    assert "\n" not in str(e.value)
    monkeypatch.undo()
    assert [p.name for p in tmp_path.iterdir()] == ["ckpt.pt"]  # the temp file is gone
    assert load_checkpoint(path, require=())["step"] == 1


def test_a_disk_filling_inside_torch_save_is_the_same_one_line(tmp_path, monkeypatch):
    """Issue 54: the real torch.save wraps the write's OSError in a RuntimeError ("file write failed"), which hid
    the full disk behind a traceback. The last checkpoint stays, and a save after room is freed works."""
    import errno

    from emml.runs.diskspace import NoSpaceError

    path = tmp_path / "ckpt.pt"
    save_checkpoint(path, {"step": 1})
    real = os.fdopen

    class Full:
        """A file on a disk with room for 1,000 bytes."""

        def __init__(self, fh):
            self.fh, self.room = fh, 1000

        def write(self, data):
            if len(data) > self.room:
                raise OSError(errno.ENOSPC, "No space left on device")
            self.room -= len(data)
            return self.fh.write(data)

        def __getattr__(self, name):
            return getattr(self.fh, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

    monkeypatch.setattr(os, "fdopen", lambda fd, mode: Full(real(fd, mode)))
    with pytest.raises(NoSpaceError) as e:
        save_checkpoint(path, {"step": 2, "weights": torch.zeros(10_000)})
    assert str(e.value).startswith(f"no space left on {tmp_path} (writing ckpt.pt, left as it was)")
    monkeypatch.undo()
    assert [p.name for p in tmp_path.iterdir()] == ["ckpt.pt"]  # the temp file is gone
    assert load_checkpoint(path, require=())["step"] == 1
    save_checkpoint(path, {"step": 3, "weights": torch.zeros(10_000)})  # room again: the same command goes on
    assert load_checkpoint(path, require=())["step"] == 3
