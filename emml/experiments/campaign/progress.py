"""A campaign's status (`emml campaign status NAME`): each run done / running / interrupted / to do with its frames,
and the time left, estimated from this machine's own runs of the same profile and from a GPU node's measured
rate."""

from __future__ import annotations

import os
import statistics
from dataclasses import dataclass
from pathlib import Path

from emml.experiments.campaign.file import Campaign, step_runs
from emml.experiments.plan import PlannedRun
from emml.runs.records import mirror_point, note_once, points_or_none, torn_tail

NODE_FPS = {"quick": 360.0, "paper": 300.0}
"""Training frames/s of one run on a lent GPU node (one H100, 16 cores) with `NODE_RUNS` runs side by side, by
profile: measured there on 2026-11-26 (docs/throughput.md, 'A GPU node': 353-381 and 298-319 per run). Training
only: the evaluations add minutes per run."""
NODE_RUNS = 8
"""Runs side by side on a GPU node (the runs the measurement above packed)."""
STATES = ("done", "running", "interrupted", "to do")
"""done: finished and recorded; running: a live process holds the run's lock; interrupted: a checkpoint to resume
from; to do: nothing yet (or a reference row with no run dir here, which is trained again)."""


class CannotCount(ValueError):
    """A results CSV a campaign's steps read is damaged: its runs cannot be counted (the message names the file and
    the line). Raised rather than shown as steps of no run, which added up to a wrong total (issue 85: one garbage
    line gave 22 steps '0/0 done' and '3 runs, ~20.8 h left' of 78 runs, ~181 h)."""


@dataclass
class RunStatus:
    """One run of a campaign, as --status shows it."""

    step: str
    table: str
    profile: str
    run_name: str
    state: str
    """One of STATES."""
    frames: int
    """Frames trained so far (the run's metrics mirror; its row when done)."""
    target: int
    """Frames the step trains it to."""
    holder: dict | None = None
    """Who trains it (pid, host) when running."""
    seconds_left: float | None = None
    """Estimated seconds to finish it on this machine; None when no run of its profile was measured here."""
    node_seconds_left: float | None = None
    """Estimated seconds of training to finish it on a GPU node, `NODE_RUNS` runs side by side (`NODE_FPS`)."""


def status(campaign: Campaign, run_root: str | None = None, results_root: str | None = None) -> list[RunStatus]:
    """Every run of the campaign in order (a run two steps share is listed once, at its first step), each read through
    its planned run (emml/experiments/plan.py): its folder, config, name and state as its launch has them. Each table
    is planned once per profile. `CannotCount` when a results CSV its steps read is damaged."""
    from emml.config.profiles import resolve_profile
    from emml.experiments.plan import plan_runs, root_fields
    from emml.runs.rundir import METRICS
    from emml.runs.runlock import holder

    planned: dict[tuple[str, str], list[PlannedRun]] = {}
    fields = root_fields(run_root, results_root)
    for step in campaign.steps:
        key = (step.table, step.profile)
        if key not in planned:  # planning reads every run dir's checkpoint: once per table and profile
            try:
                planned[key] = plan_runs(step.table, resolve_profile(step.profile), fields)
            except ValueError as e:  # a damaged results CSV (ResultsError names it and the line): left out, its
                # steps were counted as no run at all
                raise CannotCount(
                    f"campaign {campaign.name}: cannot count its runs: {e} (step {step.name} and every step of "
                    f"{step.table} [{step.profile}] read it); fix or remove that line, then ask again"
                ) from None
    speed = _Speed([run for runs in planned.values() for run in runs])
    out, seen = [], set()
    for step in campaign.steps:
        for run in step_runs(step, planned[(step.table, step.profile)]):
            directory, cfg = run.directory, run.cfg
            if directory in seen:
                continue
            seen.add(directory)
            target = cfg.num_updates * cfg.frames_per_update
            who = holder(directory)
            frames = _frames_logged(directory / METRICS)
            if run.state == "finished":
                state, frames = "done", max(frames, target)
            elif who is not None:
                state = "running"
            elif run.state in ("partial", "unrecorded"):
                state = "interrupted"
            else:
                state, frames = "to do", 0
            left = None if state == "done" else speed.seconds(cfg, max(target - frames, 0))
            fps = NODE_FPS.get(step.profile)
            node = None if state == "done" or not fps else max(target - frames, 0) / fps
            out.append(RunStatus(step.name, step.table, step.profile, run.name, state, frames, target, who, left, node))
    return out


def wall_seconds(rows: list[RunStatus], at_once: int, node: bool = False) -> float:
    """Estimated wall-clock seconds to finish the campaign with `at_once` runs side by side: each step is a launch
    (emml.experiments.launch.run_table) whose queue fills the free slot in the step's order, and the next step starts
    when the step's last run ends. Runs with no estimate (``seconds_left`` None) count 0. ``node``: from the GPU-node
    estimates (``node_seconds_left``) instead of this machine's."""
    steps: dict[str, list[float]] = {}
    for r in rows:
        if r.state != "done":
            steps.setdefault(r.step, []).append((r.node_seconds_left if node else r.seconds_left) or 0.0)
    total = 0.0
    for seconds in steps.values():
        slots = [0.0] * max(1, at_once)
        for s in seconds:
            slots[slots.index(min(slots))] += s
        total += max(slots)
    return total


def _frames_logged(metrics: Path) -> int:
    """The last frame a run's metrics mirror holds (0 without one): read from its tail, cheaply. A torn last line
    (a live run writing it, or a kill) is left out; a line that is no metric point is named and skipped (issue 54:
    one damaged run dir does not stop --status)."""
    if not metrics.exists():
        return 0
    with open(metrics, "rb") as f:
        f.seek(0, os.SEEK_END)
        start = max(0, f.tell() - 4096)
        f.seek(start)
        data = f.read()
    lines = data[: torn_tail(data)].decode(errors="replace").split("\n")[1:-1]  # the first: the header or cut
    steps = []
    for line in lines:
        point = mirror_point(line)
        if point is None:
            note_once(f"{metrics}: a line near its end is not a metric point (step,key,value): {line[:60]!r}; skipped")
            continue
        steps.append(point[0])
    return max(steps, default=0)


RECENT_RUNS = 3
"""Runs an estimate reads: the most recently trained of the closest kind. The loop's speed changed over the campaign
(issue 'loop at half the model's speed') and a run slowed by a benchmark beside it is one of several: each run's own
median, then their median."""


class _Speed:
    """This machine's measured cost of a profile: training frames/s and the seconds of one evaluation, each the median
    over the `RECENT_RUNS` most recently trained closest runs of that run's own median (`charts/fps`, `perf/eval_s`
    in its metrics mirror), among the planned runs ``runs`` (each run dir read once, however many plans hold it):
    same model and domain first."""

    def __init__(self, runs: list[PlannedRun]):
        self._dirs = {run.directory: run.cfg for run in runs}
        self._cache: dict[tuple[str, str, str], tuple[float | None, float | None]] = {}

    def measured(self, cfg) -> tuple[float | None, float | None]:
        from emml.runs.rundir import METRICS, last_started

        model, difficulty = cfg.model, cfg.env.difficulty
        key = (cfg.profile, model, difficulty)
        if key not in self._cache:
            here = {d: c for d, c in self._dirs.items() if c.profile == cfg.profile and (d / METRICS).exists()}
            # the closest runs measured here: the same model in the same domain (a House episode is 420 steps and
            # its maps larger), then any model there, then the same model anywhere, then any run of the profile
            closest = (
                lambda c: c.model == model and c.env.difficulty == difficulty,
                lambda c: c.env.difficulty == difficulty,
                lambda c: c.model == model,
                lambda c: True,
            )
            dirs = []
            for close in closest:
                dirs = [d for d, c in here.items() if close(c)]
                if dirs:
                    break
            dirs.sort(key=lambda d: (last_started(d), str(d)))  # the latest last; stable by name
            fps, evals = [], []
            for directory in dirs[-RECENT_RUNS:]:
                points = points_or_none(directory / METRICS, "not used to estimate the time left")  # damaged: named
                for values, name in ((fps, "charts/fps"), (evals, "perf/eval_s")):
                    named = [value for _, key_, value in points or [] if key_ == name]
                    if named:
                        values.append(statistics.median(named))
            self._cache[key] = (
                statistics.median(fps) if fps else None,
                statistics.median(evals) if evals else None,
            )
        return self._cache[key]

    def seconds(self, cfg, frames_left: int) -> float | None:
        fps, eval_s = self.measured(cfg)
        if not fps:
            return None
        evals = frames_left // cfg.eval_every if cfg.eval_every else 0
        final = getattr(cfg, "final_eval_episodes", cfg.eval_episodes) / max(cfg.eval_episodes, 1)
        return frames_left / fps + (eval_s or 0.0) * (evals + final)


def runs_at_once(jobs: int, device: str) -> int:
    """`jobs`, or when 0 what a launch on `device` would take (emml.experiments.launch.default_jobs); a device that is
    not one, or (for the default) that this machine lacks, is a ValueError naming it (`emml campaign --status`)."""
    from emml.config.schema import check_device_name
    from emml.experiments.launch import default_jobs
    from emml.rl.hardware import check_device

    try:
        check_device_name(device)
        if not jobs:
            check_device(device)
    except ValueError as e:
        raise ValueError(f"{e} (or give --jobs N to estimate for N runs at a time)") from None
    return jobs or default_jobs(device)


def status_text(plan, rows, at_once: int = 1, device: str = "cpu") -> str:
    """--status as text: one line per run, by step, and the estimated time left with `at_once` runs side by side."""

    def hours(seconds: float | None) -> str:
        return "?" if seconds is None else f"{seconds / 3600:.1f} h"

    lines = [f"{plan.name}: {plan.title}"]
    width = max((len(r.run_name) for r in rows), default=0)
    for step in plan.steps:
        mine = [r for r in rows if r.step == step.name]
        done = sum(r.state == "done" for r in mine)
        cost = ""
        if done < len(mine):
            here = sum(r.seconds_left or 0.0 for r in mine if r.state != "done")
            node = wall_seconds(mine, NODE_RUNS, node=True)
            cost = f"; ~{hours(here)} here, ~{node / 60:.0f} min of a GPU node ({NODE_RUNS} at a time, training)"
        lines.append(f"{step.name} ({step.table} [{step.profile}]): {done}/{len(mine)} done{cost}")
        lines.append(f"  decides: {', '.join(step.claims)}" if step.claims else "  decides: no claim (an experiment)")
        for r in mine:
            who = f" pid {r.holder.get('pid')} on {r.holder.get('host')}" if r.holder else ""
            left = "" if r.state == "done" else f", ~{hours(r.seconds_left)} left"
            lines.append(f"  {r.state:<11} {r.run_name:<{width}} {r.frames:>10,}/{r.target:,} frames{left}{who}")
    todo = [r.seconds_left for r in rows if r.state != "done"]
    unknown = sum(s is None for s in todo)
    total = sum(s for s in todo if s is not None)
    measured = "training frames/s and evaluation seconds measured from this machine's runs of each profile"
    if at_once == 1:
        left = f"~{hours(total)} on this machine (one at a time; {measured})"
    else:  # each step a launch of `at_once` slots; a step of one run holds the machine alone (`wall_seconds`)
        left = (
            f"~{hours(total)} of run time, ~{hours(wall_seconds(rows, at_once))} on this machine with {at_once} "
            f"runs at a time on {device}, step by step (--jobs; {measured}, under the packing they trained at)"
        )
    lines.append(
        f"left: {len(todo)} runs, {left}"
        + (f"; {unknown} runs of a profile not yet measured here are not counted" if unknown else "")
    )
    return "\n".join(lines)
