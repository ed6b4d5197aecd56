"""The commits a run trained under: a run stopped and resumed under another commit (a campaign pinned at a
new sha, a checkout moved on) is a chain of segments, each a session of training with its git sha and the frames it
trained. The results row names one commit (`git_sha`: the one that finished the run); results.json names them all.

- ``segments.json`` beside the checkpoint: each session's sha and the frame it started from, noted when the trainer
  opens the run (`begin_segment`, one call in emml/rl/trainer.py). A session resumed from frame F replaces every
  noted session that started at F or later (their updates past the checkpoint were lost with the process).
- results.json's ``segments``: ``[{"git_sha", "frames": [from, to], "started_at"}, ...]``, a segment ending where
  the next began and the last at the run's final frames (`run_segments`, read by `emml.runs.rundir.results_payload`).
- Run dirs from before (no ``segments`` in results.json) read as one segment of their single ``git_sha``
  (`read_run_segments`): nothing is guessed, and the table page says which runs record only their last commit
  (emml/report/commits.py).

This module reads and writes segments.json alone and imports nothing of a run dir's other files: what needs
results.json too (when a run last began training, `emml.runs.rundir.last_started`) is the run dir's owner's.
"""

from __future__ import annotations

import json
from datetime import datetime, timezone
from pathlib import Path

from emml.runs.atomic import write_text

SEGMENTS = "segments.json"
"""The run dir's file of the sessions that trained it (`begin_segment`)."""
UNKNOWN = "unknown"
"""The sha of frames trained before segments were noted (a run begun under older code, resumed under this)."""


def noted(directory: str | Path) -> list[dict]:
    """The sessions noted in ``directory``'s segments.json ([] when absent or unreadable: a torn file is noted again
    from the next session on)."""
    try:
        data = json.loads((Path(directory) / SEGMENTS).read_text())
    except (OSError, ValueError):
        return []
    rows = data.get("segments") if isinstance(data, dict) else None
    return [s for s in rows or [] if isinstance(s, dict) and isinstance(s.get("from_frame"), int)]


def begin_segment(directory: str | Path, git_sha: str, frames: int, now: str | None = None) -> list[dict]:
    """Note that a session under ``git_sha`` trains the run in ``directory`` from ``frames`` (0: a new run; else the
    checkpoint it resumes). Sessions noted from ``frames`` on are dropped (their updates past that checkpoint are
    gone); frames before the first noted session (a run begun before segments were noted) are `UNKNOWN`'s. Returns
    the sessions noted."""
    directory = Path(directory)
    kept = [s for s in noted(directory) if s["from_frame"] < frames]
    if frames > 0 and not kept:
        kept = [{"git_sha": UNKNOWN, "from_frame": 0, "started_at": None}]
    now = now or datetime.now(timezone.utc).isoformat(timespec="seconds")
    kept.append({"git_sha": git_sha, "from_frame": int(frames), "started_at": now})
    directory.mkdir(parents=True, exist_ok=True)
    write_text(directory / SEGMENTS, json.dumps({"segments": kept}, indent=2))  # whole or not at all
    return kept


def run_segments(directory: str | Path, frames: int, git_sha: str) -> list[dict]:
    """results.json's ``segments`` for a run that ends at ``frames`` under ``git_sha``: each noted session with the
    frames it trained ([from, to): to the next session's start, the last to ``frames``); one segment of ``git_sha``
    over the whole run where no session was noted."""
    sessions = noted(directory)
    if not sessions:
        return [{"git_sha": git_sha, "frames": [0, int(frames)], "started_at": None}]
    ends = [s["from_frame"] for s in sessions[1:]] + [int(frames)]
    return [
        {"git_sha": s.get("git_sha") or UNKNOWN, "frames": [s["from_frame"], end], "started_at": s.get("started_at")}
        for s, end in zip(sessions, ends)
    ]


def read_run_segments(results: dict) -> tuple[list[dict], bool]:
    """A results.json's (or a results row's) segments, and whether it recorded them: a run from before has one, its
    single ``git_sha`` over its ``frames`` (False: that sha is only the commit that finished it)."""
    segments = results.get("segments")
    if isinstance(segments, list) and segments:
        return segments, True
    frames = results.get("frames")
    frames = int(frames) if frames is not None and frames == frames else 0  # NaN: an empty CSV cell
    return [{"git_sha": str(results.get("git_sha") or UNKNOWN), "frames": [0, frames], "started_at": None}], False


def commits(segments: list[dict]) -> list[tuple[str, int, int]]:
    """(sha, from, to) per commit in training order, consecutive sessions under one commit merged."""
    out: list[tuple[str, int, int]] = []
    for s in segments:
        sha, (lo, hi) = str(s.get("git_sha") or UNKNOWN), s["frames"]
        if out and out[-1][0] == sha:
            out[-1] = (sha, out[-1][1], int(hi))
        else:
            out.append((sha, int(lo), int(hi)))
    return out


def describe(segments: list[dict]) -> str:
    """'9aa2a54 frames 0–400,384, 55cec5d frames 400,384–5,000,448'."""
    return ", ".join(f"{sha} frames {lo:,}–{hi:,}" for sha, lo, hi in commits(segments))
