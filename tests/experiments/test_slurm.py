"""Slurm packs through submitit's local executor (a real job process, its time limit and USR2 as on Slurm): k runs
per job side by side, the job requeued at its time limit and each run resumed, not restarted; one tracking store per
job, imported after."""

import json
import time
from pathlib import Path

import pytest

from emml.experiments.launch import run_table
from emml.experiments.slurm import job_store, packs
from emml.runs.atomic import write_text
from emml.runs.checkpoint import save_checkpoint
from emml.runs.naming import run_name
from emml.runs.rundir import CHECKPOINT, RESULTS, record_result, run_dir


def resumable_train(cfg, quiet=False, parent_run_id=None):
    """A training that saves its progress every step and resumes from it (module level: picklable): its first start
    trains until it is stopped (the pack's time limit: SIGTERM raises SystemExit here, the steps done are saved);
    a later start takes 3 more steps and records the run finished. Each start appends where it began to
    starts.jsonl."""
    import os

    folder = run_dir(cfg)
    folder.mkdir(parents=True, exist_ok=True)
    progress, starts = folder / "progress.txt", folder / "starts.jsonl"
    step = int(progress.read_text()) if progress.exists() else 0  # a torn write would read '' here
    end = step + 3 if starts.exists() else None  # the first start never ends by itself
    start = {"from": step, "threads": cfg.threads, "store": os.environ.get("MLFLOW_TRACKING_URI")}
    with open(starts, "a") as f:
        f.write(json.dumps(start) + "\n")
    while end is None or step < end:
        time.sleep(0.05)
        step += 1
        write_text(progress, str(step))  # whole or not at all, as a checkpoint: a stop mid-write leaves the last step
    payload = {"run_name": run_name(cfg), "table": cfg.table, "frames": cfg.frames, "seed": cfg.seed, "run_id": "x",
               "metrics": {"sgn_test": 0.5, "eqa_test": 0.25}}  # fmt: skip
    save_checkpoint(folder / CHECKPOINT, {"finished": True})
    (folder / RESULTS).write_text("{}")
    record_result(payload, cfg)


@pytest.mark.parametrize(
    ("pack", "only", "threads"),
    [
        (2, {"model": "da_no_sa"}, 2),  # its two runs (aux, no aux) side by side in one job, each in its own process
        (1, {"model": "da_no_sa", "aux": "true"}, 4),  # one run: in the job's own process
    ],
)
def test_a_job_trains_its_pack_and_requeues_itself_at_its_time_limit(tracking, no_leftovers, pack, only, threads):
    pytest.importorskip("submitit")
    report = run_table(
        "table3",
        "smoke",
        backend="slurm",
        slurm_cluster="local",
        only=only,
        pack=pack,
        cpus=4,
        # 60 s a job, USR2 at 30 s: the first start is stopped there; a later one has 30 s to start its processes and
        # finish (with 10 s, a loaded machine's pack of 2 was stopped before its processes began, three times over)
        time_min=1.0,
        signal_delay_s=30,
        wait=True,
        run_root=tracking["run_root"],
        results_root=tracking["results_root"],
        train_fn=resumable_train,
        log=lambda m: None,
    )
    store = Path(tracking["run_root"]) / "slurm" / "table3-smoke" / "pack0" / "mlflow.db"
    assert len(report.submitted) == 1 and report.failed == {}
    assert sorted(report.done) == ["da_no_sa-easy-aux-s0-smoke", "da_no_sa-easy-noaux-warm400000-s0-smoke"][:pack]
    for name in report.done:
        folder = Path(tracking["run_root"]) / "table3" / name
        starts = [json.loads(line) for line in (folder / "starts.jsonl").read_text().splitlines()]
        assert len(starts) == 2 and starts[0]["from"] == 0  # requeued at the time limit ...
        assert starts[1]["from"] > 0  # ... and resumed, not restarted
        assert {s["threads"] for s in starts} == {threads}  # the job's 4 CPUs shared by its runs
        assert {s["store"] for s in starts} == {f"sqlite:///{store.resolve()}"}  # the job's own store
        assert int((folder / "progress.txt").read_text()) == starts[1]["from"] + 3
    assert _parent_status(report) == "FINISHED"  # issue 65: it stayed RUNNING for ever


def _parent_status(report) -> str:
    from emml.runs.store import find_runs

    (parent,) = [r for r in find_runs(report.table) if r["run_id"] == report.parent_run_id]
    return parent["status"]


def killed_train(cfg, quiet=False, parent_run_id=None):
    """A training whose job is killed outright (kill -9: the OOM killer, a lost node), module level: picklable."""
    import os
    import signal

    os.kill(os.getpid(), signal.SIGKILL)


def test_a_lost_job_says_that_rerunning_resumes_and_the_parent_run_ends_failed(tracking, no_leftovers):
    """Issue 65: a killed job was reported as 'UncompletedJobError: … has not produced any output', with no hint that
    rerunning the same command resumes, and the table's parent MLflow run stayed RUNNING."""
    pytest.importorskip("submitit")
    only = {"model": "da_no_sa", "aux": "true"}
    report = run_table("table3", "smoke", backend="slurm", slurm_cluster="local", only=only, wait=True,
                       run_root=tracking["run_root"], results_root=tracking["results_root"], train_fn=killed_train,
                       log=lambda m: None)  # fmt: skip
    (why,) = report.failed.values()
    assert why.startswith(f"its Slurm job {report.submitted[0]} ended without finishing (UncompletedJobError: ")
    assert why.endswith("rerun the same command to resume them") and "\n" not in why
    assert _parent_status(report) == "FAILED"


def test_packs_and_their_stores():
    assert packs(list(range(5)), 2) == [[0, 1], [2, 3], [4]]
    with pytest.raises(ValueError, match="pack=0 must be >= 1"):
        packs([1], 0)
    assert job_store(Path("/tmp/x"), 0, "http://mlflow:5000") is None  # a server takes every job's writes
    assert (
        job_store(Path("/tmp/emml-slurm-test"), 3, "sqlite:///m.db") == "sqlite:////tmp/emml-slurm-test/pack3/mlflow.db"
    )


def test_a_bad_pack_is_refused_before_anything_runs(tracking):
    with pytest.raises(ValueError, match="pack=0 must be a whole number of runs per Slurm job"):
        run_table("table3", "smoke", backend="slurm", pack=0, run_root=tracking["run_root"])


def finished_train(cfg, quiet=False, parent_run_id=None):
    """A training that records its run finished at once (module level: picklable)."""
    folder = run_dir(cfg)
    folder.mkdir(parents=True, exist_ok=True)
    payload = {"run_name": run_name(cfg), "table": cfg.table, "frames": cfg.frames, "seed": cfg.seed, "run_id": "x",
               "metrics": {"sgn_test": 0.5, "eqa_test": 0.25}}  # fmt: skip
    save_checkpoint(folder / CHECKPOINT, {"finished": True})
    (folder / RESULTS).write_text("{}")
    record_result(payload, cfg)


def test_a_launch_without_wait_leaves_its_parent_running_and_the_next_launch_ends_it(tracking, no_leftovers):
    """Issue 85 item 6: a Slurm launch that returns after submission leaves the table's parent run RUNNING (its jobs
    go on) and says so in its folder; the next launch, finding every run finished, ends it FINISHED."""
    pytest.importorskip("submitit")
    from emml.experiments.launch import PARENT_LEFT_RUNNING

    only = {"model": "da_no_sa", "aux": "true"}
    kw = {"run_root": tracking["run_root"], "results_root": tracking["results_root"], "log": lambda m: None}
    report = run_table("table3", "smoke", backend="slurm", slurm_cluster="local", only=only, wait=False,
                       train_fn=finished_train, **kw)  # fmt: skip
    left = Path(tracking["run_root"]) / "slurm" / "table3-smoke" / PARENT_LEFT_RUNNING
    assert left.read_text().strip() == report.parent_run_id
    assert _parent_status(report) == "RUNNING"
    results = Path(tracking["results_root"]) / "table3" / "smoke.csv"
    deadline = time.monotonic() + 120  # the job's process records its run (a guard, not the assertion)
    while not results.exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    again = run_table("table3", "smoke", only=only, train_fn=finished_train, **kw)
    assert again.skipped == ["da_no_sa-easy-aux-s0-smoke"] and again.parent_run_id is None
    assert _parent_status(report) == "FINISHED" and not left.exists()
