"""A table's runs as Slurm jobs through submitit, packed: each job holds one GPU (or none) and trains ``pack`` runs side
by side on it, each in its own process with the job's CPUs shared out (Sample Factory's experiments per GPU: one run
leaves a node's GPU mostly idle, docs/throughput.md). At its time limit a job stops its runs (each saves its finished
updates, as at Ctrl-C) and requeues itself (submitit's checkpointing: its USR2 signal, `Pack.checkpoint`); the next
start resumes each run from its checkpoint and skips those it finished.

Tracking: many jobs writing one sqlite store lock it. A job therefore logs to the store named by
``$MLFLOW_TRACKING_URI`` when that is a server (``http(s)://...``), and otherwise to a sqlite store of its own in its
folder; a launch that waits for its jobs imports their finished run dirs into the launcher's store after (the run
dirs' metrics mirrors hold every point: `emml import-runs`, emml/runs/import_runs.py)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from emml.experiments.plan import PlannedRun
from emml.experiments.pool import LaunchReport, collect, end_workers, run_pool, train_one

SERVER_SCHEMES = ("http://", "https://", "databricks", "postgresql", "mysql")
"""Tracking URIs that many jobs may write at once (a server, a database server); any other (sqlite, a file store)
gets one store per job."""


@dataclass
class Pack:
    """One Slurm job's runs (submitit calls it in the job): trained side by side, each in its own process; requeued at
    the time limit by `checkpoint`. Returns what a launch reports of them: {'done': [...], 'failed': {name: error},
    'busy': {name: holder}}."""

    runs: list[PlannedRun]
    """The job's runs, their configs as the launch planned them (threads: the job's CPUs shared out)."""
    parent_run_id: str | None
    """The table's MLflow parent run (None when the job logs to a store of its own)."""
    train_fn: Callable | None = None
    """Replaces the trainer (tests; must be picklable)."""
    store: str | None = None
    """The tracking URI the job's runs log to (None: the launcher's, a server)."""
    _running: dict = field(default_factory=dict, repr=False, compare=False)
    """The live run processes (sentinel → (process, args, pipe)): what `checkpoint` stops."""

    def __call__(self) -> dict:
        from emml.runs.rundir import finished_run

        report = LaunchReport("pack", "", "slurm")
        todo = [run for run in self.runs if not finished_run(run.directory)]  # a requeued job: what is left
        report.total = len(todo)
        parent = self.parent_run_id if self.store is None else None
        args = [(run, parent, self.train_fn, self.store) for run in todo]  # the job's own store: no other job writes it
        if len(args) == 1:  # one run: in the job's process (at the time limit, submitit's exit stops it as SIGTERM)
            collect(report, todo[0].name, lambda: train_one(*args[0]), print)
        else:
            run_pool(report, args, len(args), print, self._running)
        done = [run.name for run in self.runs if run not in todo] + report.done
        return {"done": done, "failed": report.failed, "busy": report.busy}

    def checkpoint(self, *args, **kwargs):
        """submitit's time-limit (or preemption) hook: stop every run (SIGTERM: each saves its finished updates and
        ends KILLED; killed after `emml.experiments.pool.STOP_GRACE_S`) and requeue this pack, which resumes them."""
        import submitit

        end_workers([child for child, _, _ in self._running.values()])
        self._running.clear()
        return submitit.helpers.DelayedSubmission(Pack(self.runs, self.parent_run_id, self.train_fn, self.store))

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["_running"] = {}  # processes are not pickled: a requeued pack starts its own
        return state


def packs(runs: list[PlannedRun], size: int) -> list[list[PlannedRun]]:
    """``runs`` cut into packs of at most ``size``, in order."""
    if size < 1:
        raise ValueError(f"pack={size} must be >= 1 (runs per Slurm job)")
    return [runs[i : i + size] for i in range(0, len(runs), size)]


def job_store(folder: Path, index: int, uri: str, cluster: str = "slurm") -> str | None:
    """The tracking URI of job ``index``: None (the launcher's) when ``uri`` is a server, or on submitit's 'debug'
    cluster (its jobs run one at a time in the launcher's process), else a sqlite store in the job's own folder."""
    if uri.startswith(SERVER_SCHEMES) or cluster == "debug":
        return None
    path = folder / f"pack{index}" / "mlflow.db"
    path.parent.mkdir(parents=True, exist_ok=True)
    return f"sqlite:///{path.resolve()}"


def submit(
    report: LaunchReport,
    runs: list[PlannedRun],
    parent_run_id: str | None,
    train_fn: Callable | None,
    folder: Path,
    pack: int = 1,
    partition: str | None = None,
    time_min: float = 24 * 60,
    gpus: int = 0,
    cpus: int = 8,
    cluster: str = "slurm",
    wait: bool = False,
    log: Callable[[str], None] = print,
    signal_delay_s: int = 120,
) -> LaunchReport:
    """One submitit job per pack of ``pack`` runs (a Slurm job array), logs in ``folder``
    (runs/slurm/<table>-<profile>/), each requeued at its time limit until its runs finish; returns after submission
    unless ``wait``, which also imports the jobs' finished run dirs into the launcher's store."""
    try:
        import submitit
    except ImportError as e:
        raise ValueError("backend='slurm' needs submitit: pip install -e '.[slurm]'") from e
    from emml.runs.store import tracking_uri

    name = f"emml-{report.table}-{report.profile}"
    if cluster == "local":  # submitit's local executor (a workstation, the tests): Slurm's time limit and signal
        executor = submitit.LocalExecutor(folder=folder)
        executor.update_parameters(name=name, timeout_min=time_min, signal_delay_s=signal_delay_s, gpus_per_node=gpus)
    else:
        executor = submitit.AutoExecutor(folder=folder, cluster=cluster)
        params = {"name": name, "timeout_min": int(time_min), "cpus_per_task": cpus}
        params["slurm_signal_delay_s"] = signal_delay_s  # USR2 this long before the limit: the pack saves, requeues
        if gpus:
            params["gpus_per_node"] = gpus
        if partition:
            params["slurm_partition"] = partition
        executor.update_parameters(**params)
    uri = tracking_uri()
    cut = packs(runs, pack)
    jobs_of = [Pack(p, parent_run_id, train_fn, job_store(folder, i, uri, cluster)) for i, p in enumerate(cut)]
    with executor.batch():
        jobs = [executor.submit(p) for p in jobs_of]
    report.submitted = [str(j.job_id) for j in jobs]
    log(f"submitted {len(jobs)} jobs of up to {pack} runs to {cluster} (logs in {folder})")
    if not wait:
        return report
    for job, p in zip(jobs, cut):
        try:
            outcome = job.result()
        except Exception as e:  # noqa: BLE001 - the job died: each of its runs is reported failed, the others go on
            why = lost_job(job.job_id, e)
            for run in p:
                report.failed[run.name] = why
                log(f"  FAILED {run.name}: {why}")
            continue
        for name in outcome["done"]:
            collect(report, name, lambda name=name: name, log)
        report.failed.update(outcome["failed"])
        report.busy.update(outcome["busy"])
    if any(p.store is not None for p in jobs_of):
        _import_finished([run for p in cut for run in p], log)
    return report


def lost_job(job_id, e: BaseException) -> str:
    """What a job that ended without its result says (killed, out of memory, its node lost: submitit's
    UncompletedJobError 'has not produced any output'), in one line, with what to do: its runs saved their
    checkpoints, and rerunning the same command resumes them (issue 65)."""
    first = (str(e).strip().splitlines() or [""])[0][:200]
    return (
        f"its Slurm job {job_id} ended without finishing ({type(e).__name__}: {first}); its runs are resumable from "
        "their checkpoints: rerun the same command to resume them"
    )


def _import_finished(runs: list[PlannedRun], log) -> None:
    """The jobs' finished run dirs into the launcher's store (`emml import-runs`)."""
    from emml.runs.import_runs import import_runs
    from emml.runs.rundir import finished_run

    dirs = [run.directory for run in runs if finished_run(run.directory)]
    if dirs:
        results = import_runs(dirs)
        log(f"imported {sum(r.outcome == 'imported' for r in results)} finished runs into this store")
