"""Campaigns: an ordered, resumable list of table runs (reproduce/campaigns/<name>.toml).

A campaign file lists `[[steps]]` in the order they are to be trained; a step names a table, a profile, which of
the table's runs (`only`: RunSpec fields, each one value or a list whose order orders the runs) and, optionally,
`frames` (a step may train a profile to fewer frames than the profile's, e.g. the paper profile's first 1.5M) and
`set` (how its runs are measured: TrainConfig.RUNTIME fields such as eval_every, which never change what a run is or
its name, e.g. the paper profile's first curve evaluated every 100k frames rather than every 500k). A step's
table is one of the paper's (reproduce/table*.toml) or an experiment beyond them, `experiments/<name>`
(reproduce/experiments/<name>.toml: a table of one's own, `emml run FILE`, whose rows are the settings an issue
measures, e.g. issue 34's x_sent readout).
`emml campaign NAME` trains every unfinished run in that order through the table launcher (emml/experiments/launch.py),
which skips finished runs and resumes interrupted ones; `--status` shows each run as done / running / interrupted / to
do with its frames and an estimate of the time left, measured from this machine's own runs of the same profile.

A run is "running" while a live process holds its lock (emml/runs/runlock.py). A campaign is long: `emml campaign`
runs it from a git worktree of the current commit (`pin_worktree`), so that editing the checkout cannot reach a
running training and every row it writes keeps that commit's sha; the runs, results and MLflow store stay the
checkout's.
"""

from __future__ import annotations

import os
import shutil
import statistics
import subprocess
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

import tomllib

from emml.config.paths import PIN_DIR, REPRODUCE_DIR, checkout_root, project_path, project_root
from emml.experiments.tables import RunSpec
from emml.runs.naming import run_name
from emml.runs.records import mirror_point, note, note_once, points_or_none, torn_tail
from emml.runs.runlock import waiting_lock

CAMPAIGNS_DIR = REPRODUCE_DIR / "campaigns"
STEP_KEYS = ("name", "table", "profile", "only", "frames", "set", "claim", "note")
TOP_KEYS = ("title", "steps")
OWN_KEYS = ("frames", "run_root", "results_root")
"""RUNTIME fields a step may not `set`: its `frames` key sets the first; the campaign's options own the roots."""
NODE_FPS = {"quick": 360.0, "paper": 300.0}
"""Training frames/s of one run on a lent GPU node (one H100, 16 cores) with `NODE_RUNS` runs side by side, by
profile: measured there on 2026-11-26 (docs/throughput.md, 'A GPU node': 353-381 and 298-319 per run). Training
only: the evaluations add minutes per run."""
NODE_RUNS = 8
"""Runs side by side on a GPU node (the runs the measurement above packed)."""
STATES = ("done", "running", "interrupted", "to do")
"""done: finished and recorded; running: a live process holds the run's lock; interrupted: a checkpoint to resume
from; to do: nothing yet (or a reference row with no run dir here, which is trained again)."""


@dataclass(frozen=True)
class Step:
    """One step of a campaign: some runs of one table under one profile."""

    name: str
    """Short label (shown by --status)."""
    table: str
    """Table name (reproduce/<table>.toml), or ``experiments/<name>`` (reproduce/experiments/<name>.toml)."""
    profile: str
    """Profile (reproduce/profiles.toml)."""
    only: dict = field(default_factory=dict)
    """RunSpec field → value or list of values (emml.experiments.launch.select_runs); lists order the runs."""
    frames: int | None = None
    """Frames to train each run to, instead of the profile's (None: the profile's)."""
    note: str = ""
    """Why the step is there (free text)."""
    claims: tuple[str, ...] = ()
    """The claims its runs decide (ids of reproduce/claims.toml, emml/experiments/claims.py); none for a step that
    measures something of ours (an experiment of an issue)."""
    settings: dict = field(default_factory=dict)
    """The step's `set`: TrainConfig.RUNTIME field → value for its runs, over the profile's (how a run is measured
    and run, e.g. eval_every; never what it is: its name and results row stay the table's)."""

    def overrides(self) -> dict:
        """The dotted TrainConfig overrides the step adds to its runs' own (emml.experiments.launch.with_overrides)."""
        return {**self.settings, **({"frames": self.frames} if self.frames is not None else {})}


@dataclass(frozen=True)
class Campaign:
    name: str
    path: Path
    title: str
    steps: tuple[Step, ...]


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


def select_steps(campaign: Campaign, names: list[str]) -> Campaign:
    """The campaign cut to the steps named (in the campaign's order, not the names'); no names: all of it. An
    unknown name fails naming the campaign's steps. E.g. a lent GPU node trains the steps a CPU is not at."""
    known = [s.name for s in campaign.steps]
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(
            f"step={unknown[0]!r} is not a step of campaign {campaign.name!r}; allowed: {', '.join(known)}"
        )
    if not names:
        return campaign
    return replace(campaign, steps=tuple(s for s in campaign.steps if s.name in names))


def list_campaigns(directory: Path = CAMPAIGNS_DIR) -> list[str]:
    return sorted(p.stem for p in directory.glob("*.toml"))


def load_campaign(name: str, directory: Path = CAMPAIGNS_DIR) -> Campaign:
    """Parse reproduce/campaigns/<name>.toml; every error names the file and the key, before any compute."""
    from emml.config.profiles import load_profiles
    from emml.experiments.claims import load_claims
    from emml.experiments.launch import ONLY_FIELDS, select_runs
    from emml.experiments.tables import table_names

    path = directory / f"{name}.toml"
    if not path.is_file():
        known = ", ".join(list_campaigns(directory)) or "none"
        raise ValueError(f"campaign {name!r} not found ({path}); known campaigns: {known}")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{path}: not valid TOML: {e}") from None
    _check_keys(path, "top level", data, TOP_KEYS)
    raw_steps = data.get("steps")
    if not isinstance(raw_steps, list) or not raw_steps:
        raise ValueError(f"{path}: 'steps' must be a non-empty array of tables ([[steps]])")
    steps, profiles = [], load_profiles()
    tables = table_names()
    known_claims = load_claims()
    names: dict[str, int] = {}
    for i, raw in enumerate(raw_steps):
        where = f"steps[{i}]"
        _check_keys(path, where, raw, STEP_KEYS)
        for key in ("name", "table", "profile"):
            if not isinstance(raw.get(key), str) or not raw[key]:
                raise ValueError(f"{path}: {where}.{key} is required (a non-empty string)")
        if raw["name"] in names:  # --step and --status name steps: two of one name would be merged silently
            raise ValueError(
                f"{path}: {where}.name={raw['name']!r} is already the name of steps[{names[raw['name']]}]; step names "
                "must be unique"
            )
        names[raw["name"]] = i
        if raw["table"] not in tables:
            raise ValueError(f"{path}: {where}.table={raw['table']!r} is unknown; allowed: {', '.join(tables)}")
        if raw["profile"] not in profiles:
            raise ValueError(f"{path}: {where}.profile={raw['profile']!r} is unknown; allowed: {', '.join(profiles)}")
        only = raw.get("only", {})
        if not isinstance(only, dict) or any(k not in ONLY_FIELDS for k in only):
            raise ValueError(f"{path}: {where}.only must be a table of fields among {', '.join(ONLY_FIELDS)}")
        frames = raw.get("frames")
        if frames is not None and (isinstance(frames, bool) or not isinstance(frames, int) or frames < 1):
            raise ValueError(f"{path}: {where}.frames={frames!r} must be a positive integer")
        step = Step(
            raw["name"],
            raw["table"],
            raw["profile"],
            only,
            frames,
            raw.get("note", ""),
            _claims(path, where, raw, known_claims),
            _settings(path, where, raw),
        )
        try:  # the selection names runs the table has (the values present are named otherwise)
            selected = select_runs(_declared(step.table, step.profile), step.only)
        except ValueError as e:
            raise ValueError(f"{path}: {where}.only: {e}") from None
        _check_runs(path, where, step, selected)
        steps.append(step)
    return Campaign(name, path, str(data.get("title", name)), tuple(steps))


def _check_runs(path: Path, where: str, step: Step, selected: dict) -> None:
    """Each run of the step as it would train, validated before anything starts (its frames at least one update,
    `TrainConfig.validate`): a bad step otherwise fails when the campaign reaches it, hours in."""
    from emml.experiments.launch import with_overrides

    for spec, _ in selected.values():
        try:
            with_overrides(spec, step.overrides()).to_config(step.profile).validate()
        except ValueError as e:
            raise ValueError(f"{path}: {where} ({spec.run_name(step.profile)}): {e}") from None


def _claims(path: Path, where: str, raw: dict, known: dict) -> tuple[str, ...]:
    """The step's `claim`: one id of reproduce/claims.toml or a list of them."""
    value = raw.get("claim", [])
    ids = [value] if isinstance(value, str) else value
    if not isinstance(ids, list) or not all(isinstance(i, str) for i in ids):
        raise ValueError(f"{path}: {where}.claim must be a claim id or a list of them")
    for i in ids:
        if i not in known:
            raise ValueError(
                f"{path}: {where}.claim={i!r} is not a claim of reproduce/claims.toml; allowed: {', '.join(known)}"
            )
    return tuple(ids)


def _settings(path: Path, where: str, raw: dict) -> dict:
    """A step's `set`, checked before any compute: only how a run is measured (TrainConfig.RUNTIME less OWN_KEYS),
    each value of its field's type and range."""
    from emml.config.schema import TrainConfig, apply_overrides

    settings = raw.get("set", {})
    allowed = [name for name in TrainConfig.RUNTIME if name not in OWN_KEYS]
    if not isinstance(settings, dict) or any(k not in allowed for k in settings):
        raise ValueError(f"{path}: {where}.set must be a table of fields among {', '.join(allowed)}")
    try:
        apply_overrides(TrainConfig(), dict(settings), source=f"{where}.set").validate()
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    return dict(settings)


def _check_keys(path: Path, where: str, data, allowed: tuple[str, ...]) -> None:
    if not isinstance(data, dict):
        raise ValueError(f"{path}: {where} must be a table")
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise ValueError(f"{path}: {where}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(allowed)}")


def _declared(table: str, profile: str) -> dict:
    """Run name → (RunSpec, None) for the table's runs under the profile: what a selection is checked against,
    without reading any run dir."""
    from emml.config.profiles import profile_seeds
    from emml.experiments.tables import load_table

    return {spec.run_name(profile): (spec, None) for spec in load_table(table).runs(profile_seeds(profile))}


def step_runs(
    step: Step, run_root: str | None = None, results_root: str | None = None, states: dict | None = None
) -> list[tuple[RunSpec, str]]:
    """The step's runs in training order, each with its launcher state (emml.experiments.launch.STATES); ``states``: the
    table's
    run_states when already read (several steps of one table and profile read them once)."""
    from emml.experiments.launch import run_states, select_runs, with_overrides

    if states is None:
        states = run_states(step.table, step.profile, run_root, results_root)
    return [(with_overrides(spec, step.overrides()), state) for spec, state in select_runs(states, step.only).values()]


def status(campaign: Campaign, run_root: str | None = None, results_root: str | None = None) -> list[RunStatus]:
    """Every run of the campaign in order (a run two steps share is listed once, at its first step)."""
    from emml.experiments.launch import run_states
    from emml.runs.rundir import METRICS, run_dir
    from emml.runs.runlock import holder

    out, seen, read = [], set(), {}
    speed = _Speed()
    fields = {k: v for k, v in (("run_root", run_root), ("results_root", results_root)) if v is not None}
    for step in campaign.steps:
        key = (step.table, step.profile)
        if key not in read:  # run_states reads every run dir's checkpoint: once per table and profile
            try:
                read[key] = run_states(step.table, step.profile, run_root, results_root)
            except ValueError as e:  # a damaged results CSV (ResultsError names it): the other steps are shown
                note(f"step {step.name}: not shown: {e}")
                read[key] = None
        if read[key] is None:
            continue
        for spec, launch_state in step_runs(step, run_root, results_root, read[key]):
            cfg = spec.to_config(step.profile, **fields)
            directory = run_dir(cfg)
            if directory in seen:
                continue
            seen.add(directory)
            target = cfg.num_updates * cfg.frames_per_update
            who = holder(directory)
            frames = _frames_logged(directory / METRICS)
            if launch_state == "finished":
                state, frames = "done", max(frames, target)
            elif who is not None:
                state = "running"
            elif launch_state in ("partial", "unrecorded"):
                state = "interrupted"
            else:
                state, frames = "to do", 0
            left = None if state == "done" else speed.seconds(cfg, max(target - frames, 0))
            fps = NODE_FPS.get(step.profile)
            node = None if state == "done" or not fps else max(target - frames, 0) / fps
            out.append(
                RunStatus(step.name, step.table, step.profile, run_name(cfg), state, frames, target, who, left, node)
            )
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


class _Speed:
    """This machine's measured cost of a profile: training frames/s (median `charts/fps` of its runs here) and the
    seconds of one evaluation (median `perf/eval_s`), read from the run dirs' metrics mirrors of the closest runs:
    same model and domain first."""

    def __init__(self):
        self._cache: dict[tuple[str, str], tuple[float | None, float | None]] = {}

    def measured(self, cfg) -> tuple[float | None, float | None]:
        from emml.runs.rundir import METRICS

        difficulty = cfg.env.difficulty
        key = (cfg.profile, cfg.model, difficulty)
        if key not in self._cache:
            root = project_path(cfg.run_root)
            # the closest runs measured here: the same model in the same domain (a House episode is 420 steps and
            # its maps larger), then any model there, then the same model anywhere, then any run of the profile
            patterns = [f"{cfg.model}-{difficulty}-*", f"*-{difficulty}-*", f"{cfg.model}-*", "*"]
            files = []
            for pattern in patterns:
                files = sorted(root.glob(f"*/{pattern}-{cfg.profile}/{METRICS}"))
                if files:
                    break
            fps, evals = [], []
            for path in files[-6:]:  # the most recent few: enough for a median, cheap to read
                points = points_or_none(path, "not used to estimate the time left")  # damaged: named once
                for _, name, value in points or []:
                    if name == "charts/fps":
                        fps.append(value)
                    elif name == "perf/eval_s":
                        evals.append(value)
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


def run_campaign(
    campaign: Campaign,
    run_root: str | None = None,
    results_root: str | None = None,
    device: str = "cpu",
    jobs: int | None = None,
    log: Callable[[str], None] = print,
    train_fn: Callable | None = None,
) -> list:
    """Train every step's unfinished runs, step by step in the campaign's order (emml.experiments.launch.run_table per
    step); returns the steps' LaunchReports. A failed run is reported and the campaign goes on, as a table does; a stop
    (Ctrl-C, SIGTERM) ends it after the step it stopped (its report's `stopped`)."""
    from emml.experiments.launch import run_table

    reports = []
    for i, step in enumerate(campaign.steps, 1):
        log(f"[{campaign.name} {i}/{len(campaign.steps)}] {step.name}: {step.table} [{step.profile}]")
        reports.append(
            run_table(
                step.table,
                step.profile,
                jobs=jobs,
                run_root=run_root,
                results_root=results_root,
                device=device,
                log=log,
                only=step.only,
                overrides=step.overrides(),
                train_fn=train_fn,
            )
        )
        if reports[-1].stopped:  # Ctrl-C / SIGTERM: no further step starts
            break
    return reports


LOCK = "campaign.lock"
"""Under <checkout>/.campaign/: held (flock) by the one campaign training into the checkout (`hold_campaign`)."""


class CampaignRunning(ValueError):
    """Another campaign trains into this checkout (the message names its pid)."""


def campaign_lock_path() -> Path:
    """The checkout's campaign lock: one per checkout, whichever worktree the campaign runs from."""
    return checkout_root() / PIN_DIR / LOCK


def _refusal(name: str, info: dict) -> CampaignRunning:
    from emml.runs.runlock import describe

    return CampaignRunning(
        f"campaign {info.get('campaign', '?')!r} is already training into {checkout_root()}: {describe(info)}; one "
        f"campaign per checkout at a time (two would share its runs, results and MLflow store): wait for it to end "
        f"or stop it (kill {info.get('pid', '?')}), then run `emml campaign {name}` again"
    )


def check_no_campaign(name: str) -> None:
    """CampaignRunning when a live campaign holds the checkout's lock: said before a worktree is made or anything
    starts (the lock itself is taken by `hold_campaign`, in the process that trains)."""
    from emml.runs.runlock import lock_holder

    info = lock_holder(campaign_lock_path())
    if info is not None:
        raise _refusal(name, info)


@contextmanager
def hold_campaign(name: str):
    """Hold the checkout's campaign lock while the block runs; CampaignRunning (before anything starts) when another
    live campaign holds it. flock: the kernel releases it however the holder ends (`kill -9` included)."""
    from emml.runs.runlock import lock_holder, take_lock

    path = campaign_lock_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = take_lock(path, campaign=name)
    if fd is None:
        raise _refusal(name, lock_holder(path) or {})
    try:
        yield
    finally:
        os.close(fd)


def pin_worktree(root: Path, log: Callable[[str], None] = print, need: Path | None = None) -> Path:
    """A git worktree of `root`'s HEAD at <root>/.campaign/<sha>/ (made once per commit); uncommitted changes are not
    in it, and a warning says so. ``need``: a file (under ``root``) the campaign reads, which must be committed
    (a ValueError says to commit it). Concurrent starts make the worktree once (a lock around `git worktree add`),
    and one left half-made by a kill is made again."""

    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, check=True).stdout.strip()

    try:
        sha = git("rev-parse", "HEAD")
    except (OSError, subprocess.CalledProcessError) as e:
        raise ValueError(f"{root} is not a git checkout ({e}); run the campaign with --no-pin") from None
    if need is not None:
        relative = Path(need).resolve().relative_to(Path(root).resolve()).as_posix()
        try:
            git("cat-file", "-e", f"HEAD:{relative}")
        except subprocess.CalledProcessError:
            raise ValueError(
                f"{relative} is not committed: the campaign trains commit {sha[:7]} from a worktree of it "
                f"({PIN_DIR}/{sha[:12]}), which does not have it; commit it (git add {relative}; git commit), or run "
                "with --no-pin"
            ) from None
    if git("status", "--porcelain", "--untracked-files=no"):
        log(f"warning: uncommitted changes in {root} are not in the campaign's code (it runs commit {sha[:7]})")
    tree = root / PIN_DIR / sha[:12]
    (root / PIN_DIR).mkdir(exist_ok=True)
    with waiting_lock(root / PIN_DIR / "pin.lock"):  # a second start waits for the first's `git worktree add`
        if not (tree / "pyproject.toml").exists():
            if tree.exists():  # half-made by a killed start: git refuses to add over it
                shutil.rmtree(tree)
            subprocess.run(["git", "worktree", "prune"], cwd=root, capture_output=True)
            git("worktree", "add", "--detach", str(tree), sha)
    return tree


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


def run_pinned(
    name: str,
    steps: list[str],
    jobs: int = 0,
    device: str = "cpu",
    run_root: str | None = None,
    results_root: str | None = None,
    as_json: bool = False,
    log: Callable[[str], None] = print,
) -> None:
    """Re-execute `emml campaign NAME --no-pin` (the same steps and options) from a worktree of HEAD (`pin_worktree`),
    writing into this checkout's runs, results and MLflow store; does not return. A checkout that is no git one is a
    ValueError."""
    import sys

    from emml.runs.tracking import tracking_uri

    root = project_root()
    tree = pin_worktree(root, log=log, need=CAMPAIGNS_DIR / f"{name}.toml")
    # roots given are passed as absolute paths; the others resolve under this checkout there too
    # (emml.config.paths.checkout_root), each step's profile choosing its own (smoke: scratch/)
    roots = {k: str(project_path(v)) for k, v in (("--run-root", run_root), ("--results-root", results_root)) if v}
    args = [sys.executable, "-m", "emml.cli", "campaign", name, "--no-pin", "--jobs", str(jobs), "--device", device]
    args += [x for kv in roots.items() for x in kv] + [x for n in steps for x in ("--step", n)]
    args += ["--json"] if as_json else []
    env = {**os.environ, "PYTHONPATH": str(tree), "MLFLOW_TRACKING_URI": tracking_uri()}
    log(f"{name}: training from {tree} (commit {tree.name})")
    os.chdir(tree)  # `python -m` puts the working directory first on sys.path: the tree's emml, not this one's
    os.execve(sys.executable, args, env)


def resume_command(
    name: str,
    steps: list[str],
    jobs: int = 0,
    device: str = "cpu",
    run_root: str | None = None,
    results_root: str | None = None,
    plugins: list[str] = (),
) -> list[str]:
    """The command that resumes a stopped campaign: every option that changes what is resumed (the steps, the
    roots, where and how many runs at a time, the plugins its models need), and --no-pin when it did not run from
    a pinned worktree (issue 54: a resume line without the roots started new runs instead)."""
    pinned = checkout_root() != project_root()  # a pinned campaign runs from <checkout>/.campaign/<sha>
    args = ["emml", *[a for p in plugins for a in ("--plugin", p)], "campaign", name]
    args += [a for n in steps for a in ("--step", n)]
    args += ["--jobs", str(jobs)] if jobs else []
    args += ["--device", device] if device != "cpu" else []
    args += ["--run-root", str(project_path(run_root))] if run_root else []
    args += ["--results-root", str(project_path(results_root))] if results_root else []
    return args + ([] if pinned else ["--no-pin"])
