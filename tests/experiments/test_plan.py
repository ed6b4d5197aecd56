"""The plan (emml/experiments/plan.py) is the one place a run's config is built and its folder derived: a campaign's
status reads each run's folder, config, name and state through its planned run, as the launch and the report do."""

import sys
from collections import Counter
from contextlib import contextmanager
from pathlib import Path

import pytest

from emml.config.profiles import profile_seeds, resolve_profile
from emml.config.schema import TrainConfig
from emml.experiments.campaign import load_campaign, status, step_runs
from emml.experiments.plan import PlannedRun, chosen, plan_runs
from emml.experiments.tables import load_table
from emml.runs.rundir import METRICS, path_of, run_dir, variant_dir


@contextmanager
def run_paths_derived(run_root):
    """(module, function) → calls, while inside, of every emml module that derives a run's folder: `path_of`,
    `run_dir`, `variant_dir`, or a `Path.glob` under ``run_root`` (runs found by a name pattern). Caught by the
    profiler on the functions' code, so a caller is counted under whatever name it imported them."""
    run_root = Path(run_root).resolve()
    watched = {f.__code__: f.__name__ for f in (path_of, run_dir, variant_dir, Path.glob)}
    seen: Counter = Counter()

    def profile(frame, event, arg):
        if event == "call" and frame.f_code in watched:
            caller = frame.f_back.f_globals.get("__name__", "")
            globbed = frame.f_code is Path.glob.__code__ and Path(frame.f_locals["self"]).resolve()
            if caller.startswith("emml.") and (not globbed or globbed.is_relative_to(run_root)):
                seen[(caller, watched[frame.f_code])] += 1

    before = sys.getprofile()
    sys.setprofile(profile)
    try:
        yield seen
    finally:
        sys.setprofile(before)


def configs_built(monkeypatch) -> list[int]:
    """A counter of the TrainConfigs built from here on (each `__post_init__`, however the config was made)."""
    count = [0]
    post_init = TrainConfig.__post_init__

    def counted(self):
        count[0] += 1
        post_init(self)

    monkeypatch.setattr(TrainConfig, "__post_init__", counted)
    return count


CAMPAIGN = """
title = "three steps, two of one table"

[[steps]]
name = "ablations"
table = "table3"
profile = "smoke"
only = { row = ["w/o GA2", "w/o SA"], aux = true }

[[steps]]
name = "again"
table = "table3"
profile = "smoke"
only = { row = "w/o SA" }
frames = 128

[[steps]]
name = "ga"
table = "table2"
profile = "smoke"
only = { model = "ga", difficulty = "easy", aux = [true, false] }
set = { eval_every = 64 }
"""


def test_the_campaign_status_builds_each_config_once_and_derives_no_run_path(tmp_path, monkeypatch):
    """Each (table, profile) its steps read is planned once: two configs built per run (its own, and the profile's
    run its name is compared with), none rebuilt per step; every run folder read (its lock, metrics mirror, the
    runs the time left is measured from) is the planned run's `directory`, never derived or globbed by the status."""
    (tmp_path / "mine.toml").write_text(CAMPAIGN)
    campaign = load_campaign("mine", tmp_path)
    roots = (str(tmp_path / "runs"), str(tmp_path / "results"))
    seeds = profile_seeds("smoke")
    planned = sum(len(load_table(t).runs(seeds, "smoke")) for t in ("table3", "table2"))
    easy_ga = {"model": "ga", "difficulty": "easy"}
    measured = plan_runs("table2", resolve_profile("smoke"), {"run_root": roots[0]}, easy_ga)[0]
    measured.directory.mkdir(parents=True)  # a run of the profile trained here: the time left is measured from it
    (measured.directory / METRICS).write_text("step,key,value\n64,charts/fps,100.0\n64,perf/eval_s,2.0\n")
    built = configs_built(monkeypatch)
    with run_paths_derived(roots[0]) as derived:
        rows = status(campaign, *roots)
    assert [(r.step, r.run_name) for r in rows] == [
        ("ablations", "da_no_ga2-easy-aux-s0-smoke"),
        ("ablations", "da_no_sa-easy-aux-s0-smoke"),
        ("again", "da_no_sa-easy-noaux-warm400000-s0-smoke"),  # its aux run listed once, at its first step
        ("ga", "ga-easy-aux-s0-smoke"),
        ("ga", "ga-easy-noaux-warm400000-s0-smoke"),
    ]
    assert [r.target for r in rows] == [512, 512, 128, 512, 512]  # a step's frames, else the profile's
    assert all(r.seconds_left is not None for r in rows)  # measured from the run trained here
    assert built[0] <= 2 * planned, f"{built[0]} TrainConfigs for {planned} planned runs"
    assert {caller for caller, _ in derived} == {"emml.experiments.plan"}, derived


def test_a_steps_runs_are_its_launchs_runs_chosen_from_one_plan(monkeypatch):
    """A campaign step's runs, chosen from its table planned once, are the runs its launch plans (names, order,
    configs with the step's overrides), and choosing builds no config."""
    profile = resolve_profile("smoke")
    only, overrides = {"row": ["w/o SA", "w/o GA2"], "aux": True}, {"frames": 128, "eval_every": 64}
    launched = plan_runs("table3", profile, only=only, overrides=overrides)
    table = plan_runs("table3", profile)
    built = configs_built(monkeypatch)
    picked = chosen(table, only, overrides)
    assert built[0] == 0
    assert (
        [r.name for r in picked]
        == [r.name for r in launched]
        == [
            "da_no_sa-easy-aux-s0-smoke",  # the order `only` lists the rows in, not the table's
            "da_no_ga2-easy-aux-s0-smoke",
        ]
    )
    assert [r.cfg.to_dict() for r in picked] == [r.cfg.to_dict() for r in launched]
    assert {(r.cfg.frames, r.cfg.eval_every) for r in picked} == {(128, 64)}
    assert {(r.cfg.frames, r.cfg.eval_every) for r in table if r.name in {p.name for p in picked}} == {(512, 0)}


def test_a_planned_runs_folder_is_the_one_its_config_names(tmp_path):
    """`PlannedRun.directory`, from the name spelled once, is the folder the trainer writes (`run_dir`, which
    spells the name from the config), under the plan's run root, for every run of a table (borrowed ones included:
    Table 3's DA Multi-Task reads Table 2's runs)."""
    runs = plan_runs("table3", resolve_profile("smoke"), {"run_root": str(tmp_path / "runs")})
    assert {r.directory for r in runs} == {run_dir(r.cfg) for r in runs}
    assert {r.directory.parent.name for r in runs} == {"table2", "table3"}
    assert all(r.directory.is_relative_to(tmp_path / "runs") for r in runs)


def test_a_step_planned_alone_plans_its_table_under_the_roots_given(tmp_path):
    (tmp_path / "mine.toml").write_text(CAMPAIGN)
    step = load_campaign("mine", tmp_path).steps[2]
    runs = step_runs(step, run_root=str(tmp_path / "runs"), results_root=str(tmp_path / "results"))
    assert all(isinstance(r, PlannedRun) and r.state == "missing" for r in runs)
    assert [(r.name, r.cfg.eval_every) for r in runs] == [
        ("ga-easy-aux-s0-smoke", 64),
        ("ga-easy-noaux-warm400000-s0-smoke", 64),
    ]
    with pytest.raises(ValueError, match=r"--only model=nope: no run has it"):
        chosen(runs, {"model": "nope"})


def test_the_speed_is_the_median_of_the_latest_runs_own_medians(tmp_path):
    """One run's many points do not outvote the others, and a run trained long ago (older, slower code) is left out
    once three later ones of the same model and domain are there; the same model elsewhere is not read, nor a run
    dir of the profile that no plan holds."""
    import json

    from emml.experiments.campaign.progress import _Speed
    from emml.experiments.runspec import RunSpec

    def run(name, started, fps, eval_s, points=1):
        model, difficulty, aux, seed = name.split("-")
        cfg = TrainConfig(model=model, profile="smoke", run_root=str(tmp_path / "runs"), table="table2")
        cfg.env.difficulty = difficulty
        spec = RunSpec("table2", model.upper(), model, difficulty, aux == "aux", int(seed[1:]))
        planned = PlannedRun(spec, cfg, f"{name}-smoke", "finished")
        planned.directory.mkdir(parents=True)
        lines = [f"{64 * (i + 1)},charts/fps,{fps}\n{64 * (i + 1)},perf/eval_s,{eval_s}" for i in range(points)]
        (planned.directory / "metrics.csv").write_text("step,key,value\n" + "\n".join(lines) + "\n")
        segments = [{"git_sha": "abc", "from_frame": 0, "started_at": started}] if started else []
        (planned.directory / "segments.json").write_text(json.dumps({"segments": segments}))
        return planned

    runs = [
        run("ga-easy-noaux-s9", "2026-01-01T00:00:00+00:00", 10.0, 100.0, points=50),  # the oldest, last by name
        run("ga-easy-aux-s1", "2026-11-01T00:00:00+00:00", 300.0, 3.0),
        run("ga-easy-noaux-s0", "2026-11-02T00:00:00+00:00", 200.0, 4.0),
        run("ga-easy-aux-s2", "2026-11-03T00:00:00+00:00", 100.0, 5.0),
        run("ga-hard-aux-s0", "2026-11-04T00:00:00+00:00", 1.0, 1000.0),  # another domain
        run("ga-easy-aux-s4", "2026-11-05T00:00:00+00:00", 7.0, 70.0),  # the latest, but no plan holds it
    ]
    speed = _Speed([*runs[:5], runs[2]])  # a run two plans hold counts once
    # pooled points: 10; the last three by name: 100; all four runs' medians: 150; with the unplanned latest: 150
    assert speed.measured(runs[1].cfg) == (200.0, 4.0)
    assert speed.measured(runs[4].cfg) == (1.0, 1000.0)
