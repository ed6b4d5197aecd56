"""Launch every run of a table: local processes (one per run, at most `jobs` at a time), or Slurm through submitit.

Before fanning out, the MLflow experiment and one parent run per (table, profile) are created (one writer; the
sqlite store dislikes concurrent creation), and every child run is tagged with `mlflow.parentRunId`. Runs already
recorded in results/<table>/<profile>.csv are not launched; any other run is handed to the trainer, which resumes
an interrupted run from its checkpoint and re-records a finished run missing from the CSV (a fresh checkout). The
runs, their states and their selection come planned from emml/experiments/plan.py.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from emml.config.paths import project_path
from emml.config.profiles import Profile, resolve_profile
from emml.config.schema import check_choice
from emml.experiments.plan import plan_runs, root_fields
from emml.experiments.pool import STOP_GRACE_S, LaunchReport, collect, run_pool, train_one
from emml.experiments.tables import load_table

BACKENDS = ("local", "slurm")
PARENT_LEFT_RUNNING = "parent-running.txt"
"""In a Slurm launch's folder (runs/slurm/<table>-<profile>/): the id of the parent MLflow run a launch without
``wait`` left RUNNING while its jobs go on. The next launch of that table and profile ends it: FINISHED when it
finds no run left to train, else with the status its own launch ends in (`_end_parent`)."""

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


def run_table(
    name: str,
    profile: Profile | str,
    backend: str = "local",
    jobs: int | None = None,
    run_root: str | None = None,
    results_root: str | None = None,
    device: str = "cpu",
    partition: str | None = None,
    time_min: float = 24 * 60,
    gpus: int = 0,
    cpus: int = 8,
    slurm_cluster: str = "slurm",
    wait: bool = False,
    train_fn: Callable | None = None,
    log: Callable[[str], None] = print,
    only: dict | None = None,
    overrides: dict | None = None,
    pack: int = 1,
    signal_delay_s: int = 120,
) -> LaunchReport:
    """Train every unfinished run of table `name` under `profile` (`only`: those whose RunSpec fields match, e.g.
    {'difficulty': 'easy', 'seed': '0'}: a table's Easy column on a machine that cannot afford Hard; a list of values
    selects each and orders the runs by it). `overrides` (dotted TrainConfig fields, e.g. {'frames': 1_500_000})
    apply to every run on top of its table's: a campaign's step trains the paper profile to fewer frames.

    backend 'local': `jobs` concurrent runs (default: half the cores), each in its own forkserver process with
    cores // jobs torch threads; jobs=1 runs in this process. backend 'slurm' (emml/experiments/slurm.py): one
    submitit job per `pack` runs on `partition` with `time_min` minutes, `gpus` GPUs and `cpus` CPUs each (its runs
    side by side, cpus // pack threads each), requeued at its time limit (USR2 `signal_delay_s` before it) until its
    runs finish (`slurm_cluster`='local'/'debug' runs submitit's local executors, for tests); returns after
    submission unless `wait`. `train_fn` replaces the
    trainer (tests; must be picklable).
    """
    from emml.runs.tracking import parent_run, set_run_status

    check_choice("backend", backend, BACKENDS)
    if type(pack) is not int or pack < 1:
        raise ValueError(f"pack={pack!r} must be a whole number of runs per Slurm job, >= 1")
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
    fields = {**root_fields(run_root, results_root), "device": device}
    if backend == "local" and jobs > 1:
        fields["threads"] = max(1, (os.cpu_count() or 1) // jobs)
    if backend == "slurm":  # a job's runs share its CPUs (the node may have more than the job holds)
        fields["threads"] = max(1, cpus // pack)
    runs = plan_runs(name, profile, fields, only, overrides)
    report.total = len(runs)
    todo = [run for run in runs if run.state != "finished"]
    report.skipped = [run.name for run in runs if run.state == "finished"]
    folder = project_path(run_root if run_root is not None else "runs") / "slurm" / f"{name}-{profile.name}"
    if todo:  # each run's config, the store, the run and results folders, the results CSV: before the parent run
        from emml.rl.prepare import prepare

        prepare(*(run.cfg for run in todo))
    log(f"{name} [{profile.name}]: {report.total} runs, {len(report.skipped)} finished, {len(todo)} to run ({backend})")
    if not todo:
        left = folder / PARENT_LEFT_RUNNING
        if left.exists():  # a Slurm launch's jobs have finished every run since: its parent run ends here
            _end_parent(left.read_text().strip(), "FINISHED", folder)
            log(f"{name} [{profile.name}]: the parent run a Slurm launch left RUNNING ended FINISHED")
        return report
    from emml.runs.preflight import ensure_store

    ensure_store()  # a new store's tables made once, under a lock, whoever starts beside this launch
    tags = {"table": name, "profile": profile.name}
    report.parent_run_id = parent_run(name, f"{name}-{profile.name}", tags)
    set_run_status(report.parent_run_id, "RUNNING")
    from emml.envs.engine import install_signal_handlers

    install_signal_handlers()  # SIGTERM/SIGHUP raise SystemExit here as Ctrl-C raises KeyboardInterrupt
    args = [(run, report.parent_run_id, train_fn) for run in todo]
    try:
        if backend == "slurm":  # the parent run ends as a local launch's does (issue 65), once the jobs are waited for
            from emml.experiments.slurm import submit

            submit(
                report, todo, report.parent_run_id, train_fn, folder, pack=pack, partition=partition,
                time_min=time_min, gpus=gpus, cpus=cpus, cluster=slurm_cluster, wait=wait, log=log,
                signal_delay_s=signal_delay_s,
            )  # fmt: skip
            if not wait:  # the jobs go on: the parent run stays RUNNING until a later launch ends it
                from emml.runs.atomic import write_text

                write_text(folder / PARENT_LEFT_RUNNING, report.parent_run_id + "\n")
                return report
        else:
            _await_left_behind([run.cfg for run in todo], log)
            if jobs == 1:
                for a in args:
                    collect(report, a[0].name, lambda a=a: train_one(*a), log)
            else:
                run_pool(report, args, jobs, log)
    except (KeyboardInterrupt, SystemExit) as e:  # stop: the parent run ends KILLED, the caller says how to resume
        _end_parent(report.parent_run_id, "KILLED", folder)
        finished = set(report.done) | set(report.failed)
        report.stopped = stop_cause(e)
        report.unfinished = [run.name for run in todo if run.name not in finished]
        return report
    except BaseException:  # a broken pool: the parent run ends, never stays RUNNING
        _end_parent(report.parent_run_id, "FAILED", folder)
        raise
    _end_parent(report.parent_run_id, "FAILED" if report.failed else "FINISHED", folder)
    return report


def _end_parent(run_id: str, status: str, folder: Path) -> None:
    """The table's parent run ended ``status``, and the note that a Slurm launch left it RUNNING gone with it."""
    from emml.runs.tracking import set_run_status

    set_run_status(run_id, status)
    (folder / PARENT_LEFT_RUNNING).unlink(missing_ok=True)


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

    held = {d: holder(d) for d in map(run_dir, cfgs)}
    held = {d: who for d, who in held.items() if who is not None and who.get("pid") != os.getpid()}
    if not held:
        return
    first = next(iter(held.values()))
    log(f"waiting up to {wait_s:.0f} s for {len(held)} runs still held (e.g. by {describe(first)}) to be saved")
    deadline = time.monotonic() + wait_s
    while held and time.monotonic() < deadline:
        time.sleep(0.25)
        held = {d: who for d, who in held.items() if holder(d) is not None}


def _signal_name(e: SystemExit) -> str:
    import signal

    try:
        return signal.Signals(int(e.code) - 128).name
    except (TypeError, ValueError):
        return str(e.code)


def stop_cause(e: BaseException) -> str | None:
    """What stopped a command, as its stopped line says it: 'Ctrl-C' (KeyboardInterrupt), 'signal SIGTERM' (the
    SystemExit(128 + signum) of emml.envs.engine.install_signal_handlers); None for any other exit."""
    if isinstance(e, KeyboardInterrupt):
        return "Ctrl-C"
    if isinstance(e, SystemExit) and isinstance(e.code, int) and 128 < e.code < 128 + 65:
        return f"signal {_signal_name(e)}"
    return None


def stopped_line(report, again: str) -> str:
    """The one line a stopped launch ends with: what stopped, what was left, and the command that resumes it."""
    return stop_line(report.stopped, len(report.done), len(report.unfinished), again)


def stop_line(stopped: str, finished: int, unfinished: int, again: str) -> str:
    """The one line every stopped command ends with (`emml run`, `campaign`, `train`), exit 130: what stopped it,
    what was left, and the command that resumes it."""
    return (
        f"stopped by {stopped}: {finished} runs finished, {unfinished} not (those in progress ended KILLED, "
        f"resumable from their checkpoints); resume with: {again}"
    )
