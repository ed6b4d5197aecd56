"""What a training says after each update: the metrics it logs to MLflow (`update_metrics`), the console line every
`log_every` updates (`log_line`: frames, frames/s, training success per task, the losses, where the time went, the
time left), and how a line reaches a terminal, a pipe or a file (`say`). emml/rl/trainer.py calls them."""

from __future__ import annotations

import sys

import numpy as np
from tqdm import tqdm

from emml.tasks.language import TASKS


def update_metrics(
    stats: dict, fps: float, recent: dict, update: int, dropped: int, seconds: dict | None = None
) -> dict:
    """What a run logs after each update: its losses, frames/s, training success per task (last 100 episodes),
    the update count, the episodes dropped to engine deaths, and the update's seconds waiting on the envs, acting
    and learning (``perf/simulate_s``, ``perf/infer_s``, ``perf/learn_s``)."""
    metrics = {f"losses/{k}": v for k, v in stats.items()}
    metrics["charts/fps"] = fps
    for task_id, name in ((0, "sgn"), (1, "eqa")):
        if recent[task_id]:
            metrics[f"train/success_{name}"] = float(np.mean(recent[task_id]))
    metrics["charts/update"] = update
    metrics["charts/dropped_episodes"] = dropped
    for part, value in (seconds or {}).items():
        metrics[f"perf/{part}_s"] = value
    return metrics


TIME_SPLIT = ("simulate", "infer", "learn")
"""Where an update's time goes: waiting on the envs, acting, learning (the metrics ``perf/<part>_s``)."""


def time_shares(seconds: dict[str, float]) -> dict[str, float]:
    """Each part's share of the seconds given."""
    total = sum(seconds.values()) or 1.0
    return {part: v / total for part, v in seconds.items()}


def say(line: str) -> None:
    """A log line on stdout, above the progress bar when there is one, flushed: piped to a file, each line is there
    when written (and before a failure's line on stderr)."""
    tqdm.write(line)
    sys.stdout.flush()


def success_text(m: dict, task: str) -> str:
    """A task's training success (last 100 episodes) as the log lines and the bar write it: 'nan' before its first
    episode ends."""
    return f"{m.get(f'train/success_{task}', float('nan')):.2f}"


def eta_text(frames_left: int, fps: float) -> str:
    """The time left at ``fps`` frames/s, H:MM:SS."""
    seconds = round(frames_left / fps) if fps > 0 else 0
    return f"{seconds // 3600}:{seconds % 3600 // 60:02d}:{seconds % 60:02d}"


def log_line(
    update: int,
    frames: int,
    fps: float,
    m: dict,
    seconds: dict,
    tasks: tuple[str, ...] = TASKS,
    eta: str | None = None,
) -> str:
    """One line per `log_every` updates, space-separated 'name value' pairs (a file or a pipe reads it as well
    as a terminal): frames, frames/s since the previous line, training success of each task the run plays, the
    losses, then the time split and the time left."""
    split = "/".join(f"{100 * share:.0f}" for share in time_shares(seconds).values())
    return (
        f"update {update:>5} frames {frames:>9,} fps {fps:6.0f} "
        + "".join(f"{task} {success_text(m, task)} " for task in tasks)
        + f"pg {m['losses/policy']:+.3f} v {m['losses/value']:.3f} ent {m['losses/entropy']:.3f} "
        f"ans {m['losses/answer']:.3f}"
        + (f" aux {m['losses/aux']:.3f}" if "losses/aux" in m else "")
        + (f" dropped {m['charts/dropped_episodes']}" if m.get("charts/dropped_episodes") else "")
        + f" | sim/infer/learn % {split}"
        + (f" | eta {eta}" if eta is not None else "")
    )
