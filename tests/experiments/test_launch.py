"""The launcher with a fake trainer (no training here): finished runs are skipped, interrupted and unrecorded ones
go to the trainer, a failure does not stop the table, runs nest under one MLflow parent, and the Slurm path
through submitit's in-process debug executor."""

import os
from pathlib import Path

import pytest

from emml.experiments.launch import run_table
from emml.experiments.plan import run_states
from emml.runs.checkpoint import save_checkpoint
from emml.runs.naming import run_name
from emml.runs.rundir import CHECKPOINT, RESULTS, record_result, run_dir
from emml.runs.store import find_runs
from emml.runs.tracking import Tracker

PROFILE = "smoke"  # one seed: table3 has 16 runs


def fake_train(cfg, quiet=False, parent_run_id=None):
    """Stands in for emml.rl.trainer.train: logs the call and records the run as finished (module level: picklable)."""
    calls = Path(cfg.run_root) / "calls.txt"
    calls.parent.mkdir(parents=True, exist_ok=True)
    with open(calls, "a") as f:
        f.write(f"{run_name(cfg)} {parent_run_id} {cfg.threads}\n")
    if cfg.model == "da_no_ga1" and cfg.aux:
        raise RuntimeError("boom")
    payload = {
        "run_name": run_name(cfg),
        "table": cfg.table,
        "frames": cfg.frames,
        "seed": cfg.seed,
        "run_id": "fake",
        "metrics": {"sgn_test": 0.5, "eqa_test": 0.25},
    }
    save_checkpoint(run_dir(cfg) / CHECKPOINT, {"finished": True})
    (run_dir(cfg) / RESULTS).write_text("{}")
    record_result(payload, cfg)


def calls(tracking) -> list[list[str]]:
    path = Path(tracking["run_root"]) / "calls.txt"
    return [line.split() for line in path.read_text().splitlines()] if path.exists() else []


def launch(tracking, **kw):
    return run_table(
        "table3",
        PROFILE,
        run_root=tracking["run_root"],
        results_root=tracking["results_root"],
        train_fn=fake_train,
        log=lambda m: None,
        **kw,
    )


def test_finished_runs_are_skipped_and_failures_kept(tracking):
    first = launch(tracking, jobs=1)
    assert first.total == 16 and first.skipped == []
    assert len(first.done) == 15 and list(first.failed) == ["da_no_ga1-easy-aux-s0-smoke"]
    assert "boom" in first.failed["da_no_ga1-easy-aux-s0-smoke"]
    assert len(calls(tracking)) == 16
    assert {c[1] for c in calls(tracking)} == {first.parent_run_id}
    second = launch(tracking, jobs=1)  # only the failed run is tried again
    assert len(second.skipped) == 15 and list(second.failed) == ["da_no_ga1-easy-aux-s0-smoke"]
    assert len(calls(tracking)) == 17
    assert second.parent_run_id == first.parent_run_id  # one parent per (table, profile)
    parents = find_runs("table3", {"emml.role": "parent", "profile": PROFILE})
    assert len(parents) == 1 and parents[0]["status"] == "FAILED"


def test_partial_and_unrecorded_runs_go_to_the_trainer(tracking):
    states = run_states("table3", PROFILE, tracking["run_root"], tracking["results_root"])
    specs = {name: spec for name, (spec, _) in states.items()}
    partial = run_dir(
        specs["da_no_sa-easy-noaux-warm400000-s0-smoke"].to_config(PROFILE, run_root=tracking["run_root"])
    )
    save_checkpoint(partial / CHECKPOINT, {"finished": False})
    done = run_dir(specs["da_no_sa-easy-aux-s0-smoke"].to_config(PROFILE, run_root=tracking["run_root"]))
    save_checkpoint(done / CHECKPOINT, {"finished": True})
    (done / RESULTS).write_text("{}")
    states = run_states("table3", PROFILE, tracking["run_root"], tracking["results_root"])
    assert states["da_no_sa-easy-noaux-warm400000-s0-smoke"][1] == "partial"
    assert states["da_no_sa-easy-aux-s0-smoke"][1] == "unrecorded"
    assert states["dual_attention-easy-aux-s0-smoke"][1] == "missing"
    launch(tracking, jobs=1)
    called = [c[0] for c in calls(tracking)]
    assert "da_no_sa-easy-noaux-warm400000-s0-smoke" in called and "da_no_sa-easy-aux-s0-smoke" in called
    states = run_states("table3", PROFILE, tracking["run_root"], tracking["results_root"])
    assert sum(s == "finished" for _, s in states.values()) == 15


def test_process_pool(tracking):
    report = launch(tracking, jobs=2)
    assert len(report.done) == 15 and len(report.failed) == 1
    assert {c[2] for c in calls(tracking)} == {str(max(1, (__import__("os").cpu_count() or 1) // 2))}


def test_slurm_backend_through_submitit_debug_executor(tracking):
    pytest.importorskip("submitit")
    report = launch(tracking, backend="slurm", slurm_cluster="debug", partition="gpu", gpus=1, wait=True)
    assert len(report.submitted) == 16 and len(report.done) == 15 and len(report.failed) == 1
    assert (Path(tracking["run_root"]) / "slurm" / "table3-smoke").is_dir()


def test_placeholder_and_bad_arguments(tracking, placeholder_table):
    assert run_table(placeholder_table, PROFILE, log=lambda m: None).placeholder
    with pytest.raises(ValueError, match="backend"):
        run_table("table3", PROFILE, backend="k8s")
    with pytest.raises(ValueError, match="profile"):
        run_table("table3", "huge")


def test_only_trains_the_selected_runs_and_names_bad_selections(tracking):
    report = launch(tracking, jobs=1, only={"difficulty": "easy", "aux": "False"})
    assert report.total == 8 and len(report.done) == 8 and {c[0] for c in calls(tracking)} == set(report.done)
    assert all("-easy-noaux-" in c[0] for c in calls(tracking))
    with pytest.raises(ValueError, match=r"unknown field 'difficuly'; allowed fields are row, model, difficulty"):
        launch(tracking, only={"difficuly": "easy"})
    with pytest.raises(ValueError, match=r"difficulty=medium: no run has it; the values present are easy$"):
        launch(tracking, only={"difficulty": "medium"})
    assert len(calls(tracking)) == 8  # refused before any run started


def test_tracker_nests_a_child_under_its_parent(tracking):
    parent = Tracker().start("nest", "parent")
    child = Tracker().start("nest", "child", parent_run_id=parent)
    runs = {r["run_id"]: r for r in find_runs("nest")}
    assert runs[child]["tags"]["mlflow.parentRunId"] == parent


def test_cli_run_list_report(tmp_path, monkeypatch, placeholder_table):
    monkeypatch.setenv("EMML_MALLOC", "glibc-tuned")  # `emml run` would re-exec this process under tcmalloc
    import json

    from typer.testing import CliRunner

    from emml.cli import app

    runner = CliRunner()
    result = runner.invoke(app, ["run", placeholder_table, "--profile", "smoke"])
    assert result.exit_code == 0 and "placeholder" in result.output
    result = runner.invoke(app, ["run", "table2", "--profile", "huge"])
    assert result.exit_code == 2 and "profile" in result.output
    result = runner.invoke(app, ["list", "--profile", "smoke", "--json"])
    assert result.exit_code == 0, result.output
    tables = {t["table"]: t for t in json.loads(result.stdout)["tables"]}
    assert tables["table2"]["total"] == 28 and tables["table3"]["total"] == 16 and tables["table4"]["total"] == 2
    assert tables["table5"]["total"] == 7  # the House (Appendix C): 7 models, no aux, one seed under smoke
    result = runner.invoke(
        app, ["report", placeholder_table, "--profile", "smoke", "--no-curves", "--out", str(tmp_path), "--json"]
    )
    assert result.exit_code == 0, result.output
    assert (tmp_path / f"{placeholder_table}-smoke.md").exists()
    assert "PLACEHOLDER" in json.loads(result.stdout)["caption"]


def test_runs_packed_on_a_gpu_are_capped_by_its_free_memory(monkeypatch):
    import torch

    from emml.experiments import launch

    monkeypatch.setattr(launch.os, "cpu_count", lambda: 16)
    monkeypatch.setattr(torch.cuda, "mem_get_info", lambda device=None: (7 * 2**30, 80 * 2**30))
    assert launch.default_jobs("cpu") == 8
    assert launch.default_jobs("cuda") == 7 * 2**30 // launch.GPU_MEMORY_PER_RUN == 2


def test_rows_without_a_run_dir_here_are_reference_results_and_are_trained(tracking):
    # a fresh clone: the committed CSV has rows, but the runs were trained elsewhere
    launch(tracking, jobs=1)
    import shutil

    shutil.rmtree(Path(tracking["run_root"]))  # table3's runs and the Table 2 runs its DA Multi-Task row reads
    states = run_states("table3", PROFILE, tracking["run_root"], tracking["results_root"])
    assert sorted(state for _, state in states.values()) == ["missing"] + ["reference"] * 15  # 1 failed: no row
    again = launch(tracking, jobs=1)
    assert again.skipped == [] and len(again.done) == 15  # trained here (the failing fake run fails again)


def interrupted(cfg, quiet=False, parent_run_id=None):
    """Stands in for a trainer stopped by Ctrl-C (module level: picklable)."""
    raise KeyboardInterrupt


def test_an_interrupted_launch_ends_its_parent_run_and_says_what_is_left(tracking):
    report = run_table(
        "table3",
        PROFILE,
        jobs=1,
        run_root=tracking["run_root"],
        results_root=tracking["results_root"],
        train_fn=interrupted,
        log=lambda m: None,
    )
    assert report.stopped == "Ctrl-C" and len(report.unfinished) == 16 and report.done == []
    (parent,) = find_runs("table3", {"emml.role": "parent"})
    assert parent["status"] == "KILLED"  # not RUNNING forever


def test_a_child_that_died_without_sending_is_a_failed_run_not_a_broken_launch():
    """A pipe whose sender is gone reads as ready (`poll`) and then ends (EOFError): the run failed, the launch goes
    on (it used to raise EOFError out of the pool: a worker dead before its target ran, seen under heavy load)."""
    import multiprocessing
    from types import SimpleNamespace

    from emml.experiments.pool import _received

    receive, send = multiprocessing.Pipe(duplex=False)
    send.close()
    assert receive.poll()
    assert _received(receive, SimpleNamespace(exitcode=1)) == ("failed", "its process died (exit 1)")
    receive, send = multiprocessing.Pipe(duplex=False)
    send.send(("done", "a-run"))
    assert _received(receive, SimpleNamespace(exitcode=0)) == ("done", "a-run")


def locking_train(cfg, quiet=False, parent_run_id=None):
    """`fake_train` under the run's lock, as the trainer holds it (module level: picklable)."""
    from emml.runs.runlock import hold_run

    with hold_run(run_dir(cfg)):
        fake_train(cfg, quiet, parent_run_id)


def test_a_run_another_process_trains_is_reported_busy_not_failed(tracking, monkeypatch):
    """Issue 54: beside a second launch, each listed the other's runs as FAILED with a RunLocked traceback and
    exited 1, though every run trained once."""
    import emml.experiments.launch
    from emml.config.profiles import profile_config
    from emml.runs.runlock import hold_run

    monkeypatch.setattr(emml.experiments.launch, "LEFT_BEHIND_WAIT_S", 0.5)
    only = {"row": "w/o GA2", "aux": "true"}
    roots = {"run_root": tracking["run_root"], "results_root": tracking["results_root"]}
    cfg = profile_config("smoke", "easy", {"table": "table3", **roots}, model="da_no_ga2", aux=True)
    with hold_run(run_dir(cfg)):  # held by this (live) process: the pool's child is refused
        report = run_table("table3", PROFILE, jobs=2, only=only, train_fn=locking_train, log=print, **roots)
    assert list(report.busy) == ["da_no_ga2-easy-aux-s0-smoke"] and not report.failed and not report.done
    assert f"pid {os.getpid()} on host" in report.busy["da_no_ga2-easy-aux-s0-smoke"]


def test_a_launch_waits_for_a_run_left_training_by_a_killed_launcher(tracking):
    """Issue 54: a run process of a campaign killed outright takes a few seconds to save and end; the rerun waits
    for its lock instead of failing the run as locked."""
    import subprocess
    import sys
    import time

    from emml.config.profiles import profile_config
    from emml.experiments.launch import _await_left_behind

    roots = {"run_root": tracking["run_root"], "results_root": tracking["results_root"]}
    cfg = profile_config("smoke", "easy", {"table": "table3", **roots}, model="da_no_ga2", aux=True)
    code = "import sys, time; from emml.runs.runlock import hold_run\nwith hold_run(sys.argv[1]):\n" \
           "    print('held', flush=True); time.sleep(1.5)"  # fmt: skip
    holder = subprocess.Popen([sys.executable, "-c", code, str(run_dir(cfg))], stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "held"
    said, t0 = [], time.monotonic()
    _await_left_behind([cfg], said.append, wait_s=30)
    assert 0.3 < time.monotonic() - t0 < 15 and holder.wait(timeout=10) == 0
    assert len(said) == 1 and f"pid {holder.pid} on host" in said[0]
    said.clear()
    _await_left_behind([cfg], said.append, wait_s=30)  # nothing held: no wait, nothing said
    assert said == []


def test_a_launch_looks_its_profile_up_once_and_builds_each_run_once(tracking, monkeypatch):
    """The profile is resolved where the launch starts; planning its 16 runs (each config, name and state) reads
    no profiles file again, and each run's config is built once."""
    import emml.config.profiles as profiles
    import emml.experiments.plan as planner
    import emml.runs.naming as naming

    profile, table = profiles.resolve_profile(PROFILE), planner.load_table("table3")  # reading a table checks it
    lookups, built = [], []
    real_config = profiles.Profile.config

    def counted(*a, **kw):
        lookups.append(a)
        return {}

    def config(self, *a, **kw):
        built.append(kw.get("model"))
        return real_config(self, *a, **kw)

    monkeypatch.setattr(profiles, "load_profiles", counted)
    monkeypatch.setattr(naming, "load_profiles", counted)
    monkeypatch.setattr(profiles.Profile, "config", config)
    monkeypatch.setattr(planner, "load_table", lambda name: table)
    runs = planner.plan_runs(
        "table3", profile, {"run_root": tracking["run_root"], "results_root": tracking["results_root"]}
    )
    assert len(runs) == 16 and lookups == []
    assert len(built) == 2 * 16  # each run's config, and the profile's own run beside it (what its name compares to)
    monkeypatch.undo()
    assert [r.name for r in runs] == [run_name(r.cfg) for r in runs] and {r.state for r in runs} == {"missing"}


def test_a_launch_may_set_only_how_runs_run(tracking):
    """Overrides on top of a table's runs (a campaign step's frames and cadences) keep each run the table's; any
    other field is refused by name before any run starts."""
    from emml.config.profiles import resolve_profile
    from emml.experiments.plan import plan_runs

    profile = resolve_profile(PROFILE)
    plain, measured = (plan_runs("table3", profile, overrides=o) for o in (None, {"eval_every": 0, "frames": 2048}))
    assert [r.name for r in measured] == [r.name for r in plain]
    assert {(r.cfg.frames, r.cfg.eval_every) for r in measured} == {(2048, 0)}
    assert {r.spec.overrides.get("frames") for r in measured} == {2048}
    with pytest.raises(ValueError, match=r"overrides ppo\.lr: a launch may set only how a table's runs run \(frames,"):
        launch(tracking, jobs=1, overrides={"ppo.lr": 0.1, "frames": 2048})
