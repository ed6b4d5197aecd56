"""Launch every run of a table: local processes (one per run, at most `jobs` at a time), or Slurm through submitit.

Before fanning out, the MLflow experiment and one parent run per (table, profile) are created (one writer; the
sqlite store dislikes concurrent creation), and every child run is tagged with `mlflow.parentRunId`. Runs already
recorded in results/<table>/<profile>.csv are not launched; any other run is handed to the trainer, which resumes
an interrupted run from its checkpoint and re-records a finished run missing from the CSV (a fresh checkout).
"""

from __future__ import annotations

import copy
import multiprocessing
import os
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from emml.config.paths import project_path
from emml.config.profiles import Profile, resolve_profile
from emml.config.schema import TrainConfig, apply_overrides, check_choice
from emml.experiments.tables import RunSpec, Table, load_table
from emml.runs.naming import run_name

BACKENDS = ("local", "slurm")
STATES = ("finished", "unrecorded", "reference", "partial", "missing")
"""finished: a finished run dir here and its row in the results CSV; unrecorded: run dir finished but no CSV row;
reference: a CSV row with no run dir here (results committed to the repository, or made on another machine):
trained here, its row then replaced; partial: interrupted (a checkpoint, not finished); missing: nothing yet."""


GPU_MEMORY_PER_RUN = 3 * 2**30
"""Bytes of GPU memory one run may take (paper protocol at 168×300: the uint8 rollout, ~155 MB, the model and the
PPO minibatch activations, with room to spare); caps the runs packed on one GPU."""


def default_jobs(device: str = "cpu") -> int:
    """Concurrent local runs: half the cores (each run has env worker processes and a learner); on a GPU also no
    more than its free memory holds at GPU_MEMORY_PER_RUN each (the runs share it)."""
    jobs = max(1, (os.cpu_count() or 1) // 2)
    if device.startswith("cuda"):
        import torch

        free, _ = torch.cuda.mem_get_info(torch.device(device))
        jobs = max(1, min(jobs, free // GPU_MEMORY_PER_RUN))
    return jobs


@dataclass
class LaunchReport:
    """What `run_table` did."""

    table: str
    profile: str
    backend: str
    total: int = 0
    """Runs the table declares under the profile."""
    skipped: list[str] = field(default_factory=list)
    """Already finished (recorded in the results CSV): not launched."""
    done: list[str] = field(default_factory=list)
    """Trained (or resumed, or re-recorded) to the end in this launch."""
    failed: dict[str, str] = field(default_factory=dict)
    """Run name → error (the others went on)."""
    submitted: list[str] = field(default_factory=list)
    """Slurm job ids (backend slurm)."""
    parent_run_id: str | None = None
    placeholder: bool = False
    """The table is a placeholder: nothing to run."""
    stopped: str | None = None
    """Why the launch stopped early (Ctrl-C, SIGTERM): no queued run started, the runs in progress ended KILLED;
    None when it ran to the end."""
    unfinished: list[str] = field(default_factory=list)
    """After a stop: the runs it left unfinished, stopped or never started (the next launch trains them)."""
    busy: dict[str, str] = field(default_factory=dict)
    """Run name → who trains it: held by another live process (its run lock), so not trained here, nor failed."""


@dataclass(frozen=True)
class PlannedRun:
    """One run of a launch: its config built and its name spelled once (`plan_runs`), then handed to whoever trains
    it (this process, a pool worker, a Slurm job) as it is."""

    spec: RunSpec
    """What the table (and a campaign step's overrides) declares."""
    cfg: TrainConfig
    """Its TrainConfig under the launch's profile, with the launch's run_root, results_root, device, threads."""
    name: str
    """Its run name (`emml.runs.naming.run_name`)."""
    state: str
    """Its launcher state (STATES)."""


def plan_runs(
    name: str,
    profile: Profile,
    fields: dict | None = None,
    only: dict | None = None,
    overrides: dict | None = None,
) -> list[PlannedRun]:
    """Every run of table `name` under `profile`, in training order: `only` selects (`select_runs`), `overrides`
    (dotted fields of how a run runs, `with_overrides`) apply on top of each run's own; `fields` (run_root,
    results_root, device, threads) go to every run's TrainConfig."""
    fields = fields or {}
    table = load_table(name)
    planned: dict[str, PlannedRun] = {}
    recorded: dict[Path, set[str]] = {}  # per results CSV: a row may borrow another table's runs (from_table)
    for spec in table.runs(list(profile.seeds)):
        cfg = spec.to_config(profile, **fields)
        rname = run_name(cfg, profile)
        planned[rname] = PlannedRun(spec, cfg, rname, _state(cfg, rname, table, spec, recorded))
    chosen = select_runs({r.name: (r.spec, r.state) for r in planned.values()}, only or {})
    runs = [planned[rname] for rname in chosen]
    if overrides:
        runs = [_overridden(r, overrides) for r in runs]
    return runs


def _state(cfg: TrainConfig, rname: str, table: Table, spec: RunSpec, recorded: dict[Path, set[str]]) -> str:
    """The run's launcher state (STATES), from its results CSV (read once per CSV into ``recorded``) and run dir."""
    from emml.runs.results import read_results
    from emml.runs.rundir import CHECKPOINT, finished_run, path_of, results_csv

    csv = results_csv(cfg)
    if csv not in recorded:
        results = read_results(csv)
        if table.transfer is not None:  # a transfer run is recorded once its scores are in the row
            from emml.eval.transfer import metric_column

            columns = [metric_column(x) for x in spec.instructions]
            complete = set(columns) <= set(results.columns)
            results = results[results[columns].notna().all(axis=1)] if complete else results.iloc[:0]
        recorded[csv] = set(results["run_name"])
    rdir = path_of(cfg.run_root, cfg.table, rname)
    if rname in recorded[csv]:
        return "finished" if finished_run(rdir) else "partial" if (rdir / CHECKPOINT).exists() else "reference"
    if (rdir / CHECKPOINT).exists():
        return "unrecorded" if finished_run(rdir) else "partial"
    return "missing"


def _overridden(run: PlannedRun, overrides: dict) -> PlannedRun:
    spec = with_overrides(run.spec, overrides)
    return replace(run, spec=spec, cfg=apply_overrides(copy.deepcopy(run.cfg), overrides))


def run_states(name: str, profile: Profile | str, run_root: str | None = None, results_root: str | None = None) -> dict:
    """Run name → (RunSpec, state) for every run of table `name` under `profile` (see STATES)."""
    runs = plan_runs(name, resolve_profile(profile), _roots(run_root, results_root))
    return {r.name: (r.spec, r.state) for r in runs}


ONLY_FIELDS = ("row", "model", "difficulty", "aux", "seed")
"""RunSpec fields `emml run --only FIELD=VALUE` can select on."""


def select_runs(states: dict, only: dict) -> dict:
    """The runs of `states` whose fields equal every `only` value (compared as lower-case text); a value may be a
    list of allowed values, whose order then orders the runs (a campaign's step lists them in the order it wants
    them trained; otherwise the table's order). An unknown field, or a value no run has, fails by name with the
    allowed fields or the values present."""
    wanted = {
        key: [str(v).lower() for v in (value if isinstance(value, list | tuple) else [value])]
        for key, value in only.items()
    }
    for key, values in wanted.items():
        if key not in ONLY_FIELDS:
            allowed = ", ".join(ONLY_FIELDS)
            raise ValueError(f"--only {key}={only[key]}: unknown field {key!r}; allowed fields are {allowed}")
        present = sorted({str(getattr(spec, key)).lower() for spec, _ in states.values()})
        for value in values:
            if value not in present:
                raise ValueError(f"--only {key}={value}: no run has it; the values present are {', '.join(present)}")
    chosen = [
        (rname, (spec, state))
        for rname, (spec, state) in states.items()
        if all(str(getattr(spec, k)).lower() in values for k, values in wanted.items())
    ]

    def rank(item) -> tuple[int, ...]:
        return tuple(values.index(str(getattr(item[1][0], k)).lower()) for k, values in wanted.items())

    return dict(sorted(chosen, key=rank))


def with_overrides(spec: RunSpec, overrides: dict) -> RunSpec:
    """`spec` with extra dotted TrainConfig overrides after its own: only fields of how a run runs
    (`TrainConfig.RUNTIME`, e.g. a campaign step's frames), so that the run stays the one its table names."""
    other = sorted(k for k in overrides if k.split(".")[0] not in TrainConfig.RUNTIME)
    if other:
        allowed = ", ".join(TrainConfig.RUNTIME)
        raise ValueError(
            f"overrides {', '.join(other)}: a launch may set only how a table's runs run ({allowed}); "
            "declare another experiment as a row of the table"
        )
    return replace(spec, overrides={**spec.overrides, **overrides})


def _roots(run_root: str | None, results_root: str | None) -> dict:
    return {k: v for k, v in (("run_root", run_root), ("results_root", results_root)) if v is not None}


def _train_one(run: PlannedRun, parent_run_id: str | None, train_fn: Callable | None) -> str:
    """Worker body (a pool process, a Slurm job or in-process): train one run; returns its run name."""
    from emml.envs.engine import install_signal_handlers

    install_signal_handlers()
    if train_fn is None:
        from emml.rl.trainer import train as train_fn
    cfg = run.cfg.validate()
    train_fn(cfg, quiet=True, parent_run_id=parent_run_id)
    if run.spec.transfer is not None:  # Table 4: append the detectors and score the test instructions (§5.4)
        from emml.eval.transfer import record_transfer

        record_transfer(cfg, run.spec.transfer.words, run.spec.instructions, run.spec.transfer.detector)
    return run.name


def run_table(
    name: str,
    profile: Profile | str,
    backend: str = "local",
    jobs: int | None = None,
    run_root: str | None = None,
    results_root: str | None = None,
    device: str = "cpu",
    partition: str | None = None,
    time_min: int = 24 * 60,
    gpus: int = 0,
    cpus: int = 8,
    slurm_cluster: str = "slurm",
    wait: bool = False,
    train_fn: Callable | None = None,
    log: Callable[[str], None] = print,
    only: dict | None = None,
    overrides: dict | None = None,
) -> LaunchReport:
    """Train every unfinished run of table `name` under `profile` (`only`: those whose RunSpec fields match, e.g.
    {'difficulty': 'easy', 'seed': '0'}: a table's Easy column on a machine that cannot afford Hard; a list of values
    selects each and orders the runs by it). `overrides` (dotted TrainConfig fields, e.g. {'frames': 1_500_000})
    apply to every run on top of its table's: a campaign's step trains the paper profile to fewer frames.

    backend 'local': `jobs` concurrent runs (default: half the cores), each in its own forkserver process with
    cores // jobs torch threads; jobs=1 runs in this process. backend 'slurm': one submitit job per run on
    `partition` with `time_min` minutes, `gpus` GPUs and `cpus` CPUs each (`slurm_cluster`='local'/'debug' runs
    submitit's local executors, for tests); returns after submission unless `wait`. `train_fn` replaces the
    trainer (tests; must be picklable).
    """
    from emml.runs.tracking import parent_run, set_run_status

    check_choice("backend", backend, BACKENDS)
    profile = resolve_profile(profile)  # the one lookup: every run's config and name read this value
    table = load_table(name)
    report = LaunchReport(name, profile.name, backend)
    if table.placeholder:
        report.placeholder = True
        log(f"{name} is a placeholder ({table.path.name}: status = 'placeholder'); no runs are declared yet")
        return report
    jobs = jobs or default_jobs(device)
    if jobs < 1:
        raise ValueError(f"jobs={jobs} must be >= 1")
    fields = {**_roots(run_root, results_root), "device": device}
    if backend == "local" and jobs > 1:
        fields["threads"] = max(1, (os.cpu_count() or 1) // jobs)
    runs = plan_runs(name, profile, fields, only, overrides)
    report.total = len(runs)
    todo = [run for run in runs if run.state != "finished"]
    report.skipped = [run.name for run in runs if run.state == "finished"]
    if todo:  # each run's config, the store, the run and results folders, the results CSV: before the parent run
        from emml.rl.hardware import check_runnable
        from emml.runs.preflight import check_train

        check_train(*(check_runnable(run.cfg.validate()) for run in todo))
    log(f"{name} [{profile.name}]: {report.total} runs, {len(report.skipped)} finished, {len(todo)} to run ({backend})")
    if not todo:
        return report
    from emml.runs.preflight import ensure_store

    ensure_store()  # a new store's tables made once, under a lock, whoever starts beside this launch
    tags = {"table": name, "profile": profile.name}
    report.parent_run_id = parent_run(name, f"{name}-{profile.name}", tags)
    args = [(run, report.parent_run_id, train_fn) for run in todo]
    if backend == "slurm":
        folder = project_path(run_root if run_root is not None else "runs") / "slurm" / f"{name}-{profile.name}"
        return _submit(report, args, folder, partition, time_min, gpus, cpus, slurm_cluster, wait, log)
    set_run_status(report.parent_run_id, "RUNNING")
    from emml.envs.engine import install_signal_handlers

    install_signal_handlers()  # SIGTERM/SIGHUP raise SystemExit here as Ctrl-C raises KeyboardInterrupt
    try:
        _await_left_behind([run.cfg for run in todo], log)
        if jobs == 1:
            for a in args:
                _collect(report, a[0].name, lambda a=a: _train_one(*a), log)
        else:
            _pool(report, args, jobs, log)
    except (KeyboardInterrupt, SystemExit) as e:  # stop: the parent run ends KILLED, the caller says how to resume
        set_run_status(report.parent_run_id, "KILLED")
        finished = set(report.done) | set(report.failed)
        report.stopped = "Ctrl-C" if isinstance(e, KeyboardInterrupt) else f"signal {_signal_name(e)}"
        report.unfinished = [run.name for run in todo if run.name not in finished]
        return report
    except BaseException:  # a broken pool: the parent run ends, never stays RUNNING
        set_run_status(report.parent_run_id, "FAILED")
        raise
    set_run_status(report.parent_run_id, "FAILED" if report.failed else "FINISHED")
    return report


STOP_GRACE_S = 8.0
"""Seconds the pool's workers get to end their runs (checkpoint, MLflow run KILLED, engines) after a stop, before
they are killed; a second Ctrl-C kills them at once."""
LEFT_BEHIND_WAIT_S = STOP_GRACE_S + 12.0
"""Seconds a launch waits for the runs it is to train that another process still holds: a run process whose
launcher was killed outright saves and ends within `STOP_GRACE_S` of noticing (`_watch_launcher`), and the rerun
then resumes it instead of failing it as locked."""


def _await_left_behind(cfgs: list, log, wait_s: float | None = None) -> None:
    """Wait up to ``wait_s`` (default `LEFT_BEHIND_WAIT_S`) for the runs of ``cfgs`` that another live process holds
    to be released (saying so once); a run still held after that is left to `_collect`, which reports it busy."""
    import time

    wait_s = LEFT_BEHIND_WAIT_S if wait_s is None else wait_s
    from emml.runs.rundir import run_dir
    from emml.runs.runlock import describe, holder

    held = {run_dir(c): holder(run_dir(c)) for c in cfgs}
    held = {d: who for d, who in held.items() if who is not None and who.get("pid") != os.getpid()}
    if not held:
        return
    first = next(iter(held.values()))
    log(f"waiting up to {wait_s:.0f} s for {len(held)} runs still held (e.g. by {describe(first)}) to be saved")
    deadline = time.monotonic() + wait_s
    while held and time.monotonic() < deadline:
        time.sleep(0.25)
        held = {d: who for d, who in held.items() if holder(d) is not None}


def _pool(report: LaunchReport, args: list, jobs: int, log) -> None:
    """Train `args`, at most `jobs` at a time, each run in a fresh forkserver process (nothing is queued in a worker
    ahead of time, so a stop starts nothing more). On a stop (KeyboardInterrupt, SystemExit) every running child
    gets SIGTERM (its run ends KILLED, its engines by pid) and those alive after STOP_GRACE_S, or at a second
    Ctrl-C, are killed."""
    from multiprocessing.connection import wait

    from emml.envs.engine import private_mp_tempdir

    private_mp_tempdir()
    ctx = multiprocessing.get_context("forkserver")
    queue, running = list(args), {}
    # the lifeline: only this process holds its writing end, so every child sees it close however this process
    # ends, `kill -9` included, and ends its run (`_watch_launcher`) instead of training on without a launcher
    lifeline, alive = ctx.Pipe(duplex=False)
    try:
        while queue or running:
            while queue and len(running) < jobs:
                a = queue.pop(0)
                receive, send = ctx.Pipe(duplex=False)
                child = ctx.Process(target=_child, args=(send, a, lifeline), name=f"emml-{a[0].name}")
                child.start()
                send.close()
                running[child.sentinel] = (child, a, receive)
            for sentinel in wait(list(running)):
                child, a, receive = running.pop(sentinel)
                child.join()
                outcome = _received(receive, child)
                _collect(report, a[0].name, lambda outcome=outcome: _outcome(*outcome), log)
    except BaseException:
        _end_workers([child for child, _, _ in running.values()])
        raise
    finally:
        alive.close()
        lifeline.close()


def _child(send, a, lifeline=None) -> None:
    """A run's process: Ctrl-C is left to the launcher (which stops children by SIGTERM), and so is its life (the
    run ends when the launcher does, `_watch_launcher`); the outcome goes back as ('done', run name), ('stopped',
    why), ('busy', who holds the run) or ('failed', error and traceback)."""
    import signal

    from emml.runs.runlock import RunLocked

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if lifeline is not None:
        _watch_launcher(lifeline)
    try:
        outcome = ("done", _train_one(*a))
    except (KeyboardInterrupt, SystemExit) as e:
        outcome = ("stopped", type(e).__name__)
    except RunLocked as e:
        outcome = ("busy", str(e))
    except BaseException as e:  # noqa: BLE001 - reported to the launcher, which goes on with the table
        outcome = ("failed", f"{type(e).__name__}: {e}\n{traceback.format_exc(limit=3)}")
    try:
        send.send(outcome)
    except OSError:  # the launcher is gone (killed): nobody to tell, the run dir says it all
        pass


def _watch_launcher(lifeline) -> None:
    """A daemon thread that waits for the launcher's end (the lifeline's writing end closed: its process ended,
    however), then stops this run as a stop from the launcher would: SIGTERM to itself (the run saves its finished
    updates, ends KILLED in MLflow, its engines and workers end), and SIGKILL after `STOP_GRACE_S` if it has not
    ended by then. Its run lock goes with it, and a rerun of the launch resumes the run."""
    import signal
    import threading
    import time

    def watch() -> None:
        try:
            lifeline.recv()  # nothing is ever sent: returns only by EOF
        except (EOFError, OSError):
            pass
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(STOP_GRACE_S)
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="emml-launcher-watch", daemon=True).start()


def _received(receive, child) -> tuple[str, str]:
    """What a finished child sent, or ('failed', why) when it died without sending (killed, or dead before its
    target ran: the pipe is then at its end, which `poll` also reports as readable)."""
    try:
        if receive.poll():
            return receive.recv()
    except (EOFError, OSError):
        pass
    return ("failed", f"its process died (exit {child.exitcode})")


def _outcome(kind: str, detail: str) -> str:
    from emml.runs.runlock import RunLocked

    if kind == "stopped":
        raise KeyboardInterrupt
    if kind == "busy":
        raise RunLocked(detail)
    if kind == "failed":
        raise RuntimeError(detail)
    return detail


def _end_workers(workers: list) -> None:
    """SIGTERM to each live worker, a grace period to end its run, then SIGKILL (a second Ctrl-C: at once)."""
    import signal
    import time

    for w in workers:
        if w.is_alive():
            os.kill(w.pid, signal.SIGTERM)
    try:
        deadline = time.monotonic() + STOP_GRACE_S
        for w in workers:
            w.join(max(0.0, deadline - time.monotonic()))
    except KeyboardInterrupt:
        pass
    for w in workers:
        if w.is_alive():
            w.kill()
            w.join(1.0)


def _signal_name(e: SystemExit) -> str:
    import signal

    try:
        return signal.Signals(int(e.code) - 128).name
    except (TypeError, ValueError):
        return str(e.code)


def _collect(report: LaunchReport, rname: str, result: Callable[[], str], log) -> None:
    """Record the outcome of run ``rname``; a failure is kept and the launch goes on."""
    from emml.runs.runlock import RunLocked

    try:
        result()
    except RunLocked as e:  # another live process trains it: not this launch's run to train, nor a failure
        report.busy[rname] = str(e)
        log(f"  not trained here: {e}")
        return
    except Exception as e:  # noqa: BLE001 - one failed run must not stop the table
        report.failed[rname] = f"{type(e).__name__}: {e}"
        log(f"  FAILED {rname}: {e}\n{traceback.format_exc(limit=3)}")
        return
    report.done.append(rname)
    log(f"  done {rname} ({len(report.done)}/{report.total - len(report.skipped)})")


def _submit(report, args, folder, partition, time_min, gpus, cpus, cluster, wait, log) -> LaunchReport:
    """One submitit job per run (a Slurm job array), logs in `folder` (runs/slurm/<table>-<profile>/)."""
    try:
        import submitit
    except ImportError as e:
        raise ValueError("backend='slurm' needs submitit: pip install -e '.[slurm]'") from e
    executor = submitit.AutoExecutor(folder=folder, cluster=cluster)
    params = {"name": f"emml-{report.table}-{report.profile}", "timeout_min": time_min, "cpus_per_task": cpus}
    if gpus:
        params["gpus_per_node"] = gpus
    if partition:
        params["slurm_partition"] = partition
    executor.update_parameters(**params)
    with executor.batch():
        jobs = [executor.submit(_train_one, *a) for a in args]
    report.submitted = [str(j.job_id) for j in jobs]
    log(f"submitted {len(jobs)} jobs to {cluster} (logs in {folder})")
    if wait:
        for job, a in zip(jobs, args):
            _collect(report, a[0].name, job.result, log)
    return report


def stopped_line(report, again: str) -> str:
    """The one line a stopped launch ends with: what stopped, what was left, and the command that resumes it."""
    return (
        f"stopped by {report.stopped}: {len(report.done)} runs finished, {len(report.unfinished)} not (those in "
        f"progress ended KILLED, resumable from their checkpoints); resume with: {again}"
    )
