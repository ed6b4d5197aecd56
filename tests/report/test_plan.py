"""The report planned once (issue 64): a table's report resolves its profile and builds each run's config and name
once, by the launch's own plan (`emml.experiments.plan.plan_runs`), and every part of the page reads that plan."""

from emml.config.profiles import resolve_profile
from emml.experiments.tables import load_table
from emml.report.plan import plan_report
from tests.experiments.test_plan import configs_built as built
from tests.report.test_tables import PROFILE, fake_results, report


def test_a_table2_report_builds_at_most_two_configs_per_run(tmp_path, monkeypatch):
    """Table 2's report built 1,448 TrainConfigs for its 84 runs (issue 64: each part of the page, the caption, the
    LaTeX, the deviations, the sample efficiency, rebuilt every run's config to spell its name); planned once, it
    builds two per run: the run's config and the profile's baseline its name is compared with (`swept`). Counted
    apart: what a process reads once whatever it reports (the profiles file, TrainConfig's defaults per env kind) and
    loading and checking the table file (which every command that reads it pays)."""
    import emml.report.field
    from emml.experiments import fidelity

    monkeypatch.setattr(emml.report.field, "plot_field", lambda *a: [])  # the rliable figure reads the cells only
    fake_results("table2", tmp_path / "results")  # finished runs, no run dirs here: no saved config to read
    runs = len(load_table("table2").runs(list(resolve_profile(PROFILE).seeds), PROFILE))
    for difficulty in ("easy", "hard"):
        fidelity.resolve({"env": {"difficulty": difficulty}})
    count = built(monkeypatch)
    load_table("table2")
    table_file, count[0] = count[0], 0
    rep = report("table2", tmp_path)
    assert runs == 86 and all(
        c["n"] == (5 if (c["row"], c["difficulty"], c["aux"]) == ("Dual-Attention", "easy", True) else 3)
        for c in rep["cells"]
    )
    assert count[0] - table_file <= 2 * runs, f"{count[0] - table_file} TrainConfigs for {runs} runs"


def test_the_plan_holds_every_run_once_named_as_the_launch_names_it(tmp_path):
    plan = plan_report("table3", PROFILE, tmp_path / "results", tmp_path / "runs")
    specs = load_table("table3").runs(list(resolve_profile(PROFILE).seeds), PROFILE)
    assert [r.spec for r in plan.runs] == specs
    assert [r.name for r in plan.runs] == [s.run_name(PROFILE) for s in specs]
    assert plan.run_root == tmp_path / "runs" and all(r.cfg.run_root == str(tmp_path / "runs") for r in plan.runs)
    (run,) = [r for r in plan.cell_runs("w/o SA", "easy", True, "sgn_test") if r.spec.seed == 0]
    assert run.name == "da_no_sa-easy-aux-s0-quick"
    defaults = plan_report("table3", PROFILE)  # the profile's roots
    assert (defaults.run_root, defaults.results_root) == ("runs", "results")


def test_a_table_page_reads_each_run_folder_through_its_plan(tmp_path):
    """The page, its deviations and its commits footnote read each run's folder as planned (`PlannedRun.directory`):
    none of the modules that make a table page derives one from (run root, table, name) itself, whatever runs are
    there (here: one with its results.json, the others reference rows)."""
    import json

    from emml.runs.rundir import RESULTS
    from tests.experiments.test_plan import run_paths_derived

    fake_results("table3", tmp_path / "results")
    run = next(r for r in plan_report("table3", PROFILE, run_root=tmp_path / "runs").runs if r.spec.row == "w/o SA")
    run.directory.mkdir(parents=True)
    segments = [{"git_sha": "aaa", "frames": [0, 64]}, {"git_sha": "bbb", "frames": [64, 128]}]
    (run.directory / RESULTS).write_text(json.dumps({"config": run.cfg.to_dict(), "segments": segments}))
    with run_paths_derived(tmp_path / "runs") as derived:
        report("table3", tmp_path)
    page = (tmp_path / "reports" / "table3-quick.md").read_text()
    assert f"`{run.name}`: aaa frames 0–64, bbb frames 64–128" in page  # its folder's results.json was read
    callers = {caller for caller, _ in derived}
    assert "emml.experiments.plan" in callers and not callers & PAGE_MODULES, derived


PAGE_MODULES = {"emml.report.tables", "emml.report.deviations", "emml.report.commits", "emml.report.plan"}
"""The modules that make a table page and read its runs' folders."""


def test_the_index_finds_its_best_run_and_its_no_aux_run_through_the_plan(tmp_path, monkeypatch):
    """The index's best Dual-Attention run and the No-Aux run its channel figure compares with are the plan's runs
    (their folders as planned, the No-Aux run the table declares beside it), none derived by the index itself."""
    from emml.report.index import best_run, finished_no_aux
    from emml.runs.naming import run_name
    from emml.runs.rundir import CHECKPOINT
    from tests.experiments.test_plan import run_paths_derived
    from tests.report.test_index import _recorded_easy_dual_attention

    roots = {"run_root": str(tmp_path / "runs"), "results_root": str(tmp_path / "results")}
    recorded = list(_recorded_easy_dual_attention(tmp_path, monkeypatch, roots))
    plan = plan_report("table2", "demo", roots["results_root"], roots["run_root"])
    assert best_run(plan) is None  # no checkpoint here: results committed without their run dirs
    for run in plan.named(run_name(cfg) for cfg in recorded):  # the aux run and its declared No-Aux run
        run.directory.mkdir(parents=True)
        (run.directory / CHECKPOINT).write_bytes(b"not read: the best run only needs one here")
    with run_paths_derived(roots["run_root"]) as derived:
        best = best_run(plan)
        compared = finished_no_aux(plan, best)
    assert best.name == "dual_attention-easy-aux-s0-demo" and best.cfg.aux and len(recorded) == 2
    assert compared is None  # its No-Aux run's checkpoint is no finished run's
    assert plan.no_aux_of(best).name == "dual_attention-easy-noaux-warm400000-s0-demo"  # the declared one
    assert {caller for caller, _ in derived} == {"emml.experiments.plan"}, derived
