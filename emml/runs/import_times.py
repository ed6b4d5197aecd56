"""When an imported run trained (`emml import-runs`, emml/runs/import_runs.py): results.json's ``started_at`` and
``ended_at`` (UTC, written by the trainer since issue 53). A run dir from before has neither: its end is the earliest
of its files' modification times and the commit that added its results.json (each is at or after the end), its
duration its curve's frames over its frames/s plus its evaluations' seconds (`run_times`); each point is timed as
the curve's seconds stretch over that span."""

from __future__ import annotations

import bisect
import subprocess
import time
from pathlib import Path

from emml.runs.rundir import CHECKPOINT, METRICS, RESULTS, RunDirError, utc_ms


def curve_seconds(points: list[tuple[int, str, float]]) -> list[tuple[int, float]]:
    """(step, seconds of training up to it) from the curve: each update's frames over its ``charts/fps`` (frames/s
    of the run), plus each evaluation's ``perf/eval_s``; [] when the curve has no frames/s."""
    fps = sorted((st, v) for st, k, v in points if k == "charts/fps" and v > 0)
    evals = dict((st, v) for st, k, v in points if k == "perf/eval_s")
    out, total, previous = [], 0.0, 0
    for step, value in fps:
        total += (step - previous) / value + evals.get(step, 0.0)
        previous = step
        out.append((step, total))
    return out


def run_times(results: dict, run_dir: Path, points: list, committed: dict[Path, float]) -> tuple:
    """(start, end in ms, where they come from, a step's time in ms) of a run dir: results.json's ``started_at`` and
    ``ended_at`` when the trainer wrote them, else estimated (module docstring): the end from the earliest of the
    modification times of metrics.csv and checkpoint.pt and ``committed`` (the time of the commit that added its
    results.json), the start that end less the curve's seconds (`curve_seconds`). A step's time follows the curve's
    seconds, stretched over start to end (a run resumed after a pause spreads the pause)."""
    seconds = curve_seconds(points)
    lasted = seconds[-1][1] if seconds else 0.0
    try:
        start = utc_ms(results["started_at"]) if results.get("started_at") else None
        end = utc_ms(results["ended_at"]) if results.get("ended_at") else None
    except ValueError:
        raise RunDirError(f"{run_dir / RESULTS}: 'started_at' or 'ended_at' is not an ISO time") from None
    if start is not None and end is not None:
        how = RESULTS
    else:
        if end is None:
            files = [n for n in (METRICS, CHECKPOINT) if (run_dir / n).is_file()]
            bounds = {f"modified {n}": (run_dir / n).stat().st_mtime for n in files}
            if run_dir / RESULTS in committed:
                bounds[f"committed {RESULTS}"] = committed[run_dir / RESULTS]
            source, last = min(bounds.items(), key=lambda x: x[1]) if bounds else ("imported", time.time())
            end, ended = int(last * 1000), f"ended when {source}"
        else:
            ended = f"ended at {RESULTS}'s ended_at"
        start = end - int(lasted * 1000)
        how = f"estimated: {ended}, lasted the curve's frames over its frames/s ({lasted / 3600:.2f} h)"
    steps = [st for st, _ in seconds]
    frames = max((st for st, _, _ in points), default=0)

    def when(step: int) -> int:
        if lasted > 0:  # the time at the first update at or after the step
            share = seconds[min(bisect.bisect_left(steps, step), len(steps) - 1)][1] / lasted
        else:
            share = step / frames if frames else 1.0
        return start + int(min(max(share, 0.0), 1.0) * (end - start))

    return start, end, how, when


def commit_times(run_dirs: list[Path]) -> dict[Path, float]:
    """The time of the commit that added each run dir's results.json, where git knows it (one git call): the end
    of a committed run from before ``ended_at``, in a clone whose files are all as old as the clone."""
    files = [d.resolve() / RESULTS for d in run_dirs if (d / RESULTS).is_file()]
    if not files:
        return {}
    try:
        top = subprocess.run(
            ["git", "rev-parse", "--show-toplevel"], cwd=files[0].parent, capture_output=True, text=True, timeout=10
        ).stdout.strip()
        if not top:
            return {}
        out = subprocess.run(
            ["git", "log", "--diff-filter=A", "--format=%x00%ct", "--name-only", "--", *map(str, files)],
            cwd=top,
            capture_output=True,
            text=True,
            timeout=60,
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return {}
    found: dict[Path, float] = {}
    when = None
    for line in out.splitlines():
        if line.startswith("\0"):
            when = float(line[1:])
        elif line and when is not None:
            path = Path(top, line)
            found[path] = min(found.get(path, when), when)  # the first time it was added
    return found
