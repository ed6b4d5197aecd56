"""Campaigns with the launcher's fake trainer (no training here): steps train in the declared order, finished runs
are skipped on a rerun, --status shows done / running / to do with frames, a bad file fails naming the file and the
key before any run, and the pinned worktree holds the commit the campaign runs."""

import shutil
import subprocess
from pathlib import Path

import pytest

from emml.experiments.campaign import load_campaign, pin_worktree, run_campaign, status, step_runs
from emml.experiments.campaign.progress import CannotCount
from emml.experiments.tables import load_table
from emml.runs.runlock import hold_run
from tests.experiments.test_launch import calls, fake_train

CAMPAIGN = """
title = "a test campaign"

[[steps]]
name = "first"
table = "table3"
profile = "smoke"
only = { row = ["w/o GA2", "w/o SA"], aux = true }

[[steps]]
name = "second"
table = "table2"
profile = "smoke"
only = { model = "ga", difficulty = "easy", aux = [true, false] }
frames = 128
set = { eval_every = 64, eval_episodes = 2 }
"""


@pytest.fixture
def campaigns(tmp_path):
    folder = tmp_path / "campaigns"
    folder.mkdir()
    (folder / "mine.toml").write_text(CAMPAIGN)
    return folder


def test_steps_train_in_order_and_a_rerun_skips_what_is_finished(tracking, campaigns):
    plan = load_campaign("mine", campaigns)
    roots = (tracking["run_root"], tracking["results_root"])
    before = status(plan, *roots)
    assert [(r.step, r.run_name, r.state) for r in before] == [
        ("first", "da_no_ga2-easy-aux-s0-smoke", "to do"),
        ("first", "da_no_sa-easy-aux-s0-smoke", "to do"),
        ("second", "ga-easy-aux-s0-smoke", "to do"),
        ("second", "ga-easy-noaux-warm400000-s0-smoke", "to do"),
    ]
    assert before[2].target == 128 and before[0].target == 512  # a step's frames, else the profile's
    first, second = (step_runs(step, run_root=roots[0], results_root=roots[1])[0] for step in plan.steps)
    assert (second.cfg.eval_every, second.cfg.eval_episodes) == (64, 2)  # a step's set, else the profile's
    assert (first.cfg.eval_every, first.cfg.eval_episodes) == (0, 3)
    assert second.name == second.spec.run_name("smoke") == before[2].run_name  # the run's name stays the table's
    reports = run_campaign(plan, *roots, jobs=1, log=lambda m: None, train_fn=fake_train)
    assert [c[0] for c in calls(tracking)] == [r.run_name for r in before]  # the declared order
    assert [len(r.done) for r in reports] == [2, 2]
    trained = Path(tracking["run_root"]) / "calls.txt"
    trained.unlink()
    again = run_campaign(plan, *roots, jobs=1, log=lambda m: None, train_fn=fake_train)
    assert calls(tracking) == [] and [len(r.skipped) for r in again] == [2, 2]
    assert {r.state for r in status(plan, *roots)} == {"done"}


def test_status_shows_a_run_held_by_a_live_process_as_running(tracking, campaigns):
    plan = load_campaign("mine", campaigns)
    roots = (tracking["run_root"], tracking["results_root"])
    run = Path(tracking["run_root"]) / "table2" / "ga-easy-aux-s0-smoke"
    with hold_run(run):
        (run / "metrics.csv").write_text("step,key,value\n64,charts/fps,100.0\n128,charts/fps,100.0\n")
        rows = {r.run_name: r for r in status(plan, *roots)}
    held = rows["ga-easy-aux-s0-smoke"]
    assert held.state == "running" and held.frames == 128 and held.holder["pid"] > 0


@pytest.mark.parametrize(
    "text, message",
    [
        ('[[steps]]\nname = "a"\ntable = "table7"\nprofile = "smoke"\n', r"steps\[0\].table='table7' is unknown"),
        ('[[steps]]\nname = "a"\ntable = "table2"\nprofile = "huge"\n', r"steps\[0\].profile='huge' is unknown"),
        ('[[steps]]\nname = "a"\ntable = "table2"\nprofile = "smoke"\nonly = { modle = "ga" }\n', r"only must be"),
        (
            '[[steps]]\nname = "a"\ntable = "table2"\nprofile = "smoke"\nonly = { model = "gpt" }\n',
            r"model=gpt: no run",
        ),
        (
            '[[steps]]\nname = "a"\ntable = "table2"\nprofile = "smoke"\nframes = 0\n',
            r"key 'steps\[0\].frames': must be a positive integer, got 0",
        ),
        (
            '[[steps]]\nname = "a"\ntable = "table2"\nprofile = "smoke"\nepochs = 3\n',
            r"key 'steps\[0\].epochs': unknown key; allowed keys: name, table, profile, only, frames",
        ),
        (
            '[[steps]]\nname = "a"\ntable = "table2"\nprofile = "smoke"\nset = { "ppo.lr" = 1.0 }\n',
            r"key 'steps\[0\].set.ppo.lr': unknown key; allowed keys: eval_every, eval_episodes",
        ),
        ('[[steps]]\nname = "a"\ntable = "table2"\nprofile = "smoke"\nset = { eval_every = -1 }\n', r"eval_every=-1"),
        (
            '[[steps]]\nname = "a"\ntable = "table2"\nprofile = "smoke"\nset = { eval_episodes = "many" }\n',
            r"steps\[0\].set 'eval_episodes'",
        ),
        ("title = 'x'\n", r"key 'steps': missing"),
        ("title = 'x'\nsteps = []\n", r"key 'steps': must be a non-empty array of tables \(\[\[steps\]\]\), got \[\]"),
        ('[[steps]]\nname = ""\ntable = "table2"\nprofile = "smoke"\n', r"key 'steps\[0\].name': must be a non-empty"),
        ('[[steps]]\nname = "a"\ntable = "table2"\nprofile = "smoke"\nclaim = 3\n', r"claim': must be a claim id or a"),
        (  # issue 54: two steps of one name were merged by --step and --status
            '[[steps]]\nname = "a"\ntable = "table2"\nprofile = "smoke"\n' * 2,
            r"steps\[1\].name='a' is already the name of steps\[0\]; step names must be unique",
        ),
        (  # issue 54: frames below one update passed until the step's runs started, hours in
            '[[steps]]\nname = "a"\ntable = "table2"\nprofile = "smoke"\nframes = 10\n',
            r"steps\[0\] \(\S+-smoke\): frames=10 is less than one update .* the minimum is 64",
        ),
        (
            '[[steps]]\nname = "a"\ntable = "table2"\nprofile = "smoke"\nclaim = "da-is-great"\n',
            r"steps\[0\].claim='da-is-great' is not a claim of reproduce/claims.toml; allowed: da-best-easy-aux",
        ),
    ],
)
def test_a_bad_campaign_fails_naming_the_file_and_the_key(campaigns, text, message):
    (campaigns / "bad.toml").write_text(text)
    with pytest.raises(ValueError, match=message) as e:
        load_campaign("bad", campaigns)
    assert "bad.toml" in str(e.value)
    with pytest.raises(ValueError, match="known campaigns: bad, mine"):
        load_campaign("nope", campaigns)


def test_the_reference_campaign_loads():
    plan = load_campaign("reference")
    assert plan.steps[0].table == "table2" and any(s.profile == "paper" and s.frames for s in plan.steps)
    paper = next(s for s in plan.steps if s.profile == "paper")  # its curve has the quick runs' points (100k apart)
    assert paper.overrides() == {"eval_every": 100_000, "eval_episodes": 100, "frames": 1_500_000}
    experiment = next(s for s in plan.steps if s.table == "experiments/eqa_readout")  # issue 34's experiment
    assert load_table(experiment.table).name == "eqa_readout" and not experiment.claims
    # issue 50: every step of the paper's tables names the claims it decides; Hard, Table 4 Hard and Table 5 are in
    assert all(s.claims for s in plan.steps if not s.table.startswith("experiments/"))
    decided = {c for s in plan.steps for c in s.claims}
    assert {"da-best-hard-aux", "transfer-hard", "house-da-best", "da-best-easy-noaux"} <= decided
    first_hard = next(i for i, s in enumerate(plan.steps) if s.only.get("difficulty") == "hard")
    first_seeds = next(i for i, s in enumerate(plan.steps) if s.name == "seeds-1-2")
    assert first_hard < first_seeds  # a claim no run tests comes before more seeds of a decided one


def test_an_experiment_step_trains_its_own_rows_and_borrows_the_papers(tracking, campaigns):
    """A step may name a table beyond the paper's, reproduce/experiments/<name>.toml: issue 34's x_sent readout.
    Its 'last' row reads Table 2's Dual-Attention runs (trained there); its 'mean' row trains runs of its own."""
    (campaigns / "exp.toml").write_text(
        '[[steps]]\nname = "readout"\ntable = "experiments/eqa_readout"\nprofile = "smoke"\nonly = { seed = 0 }\n'
    )
    plan = load_campaign("exp", campaigns)
    roots = (tracking["run_root"], tracking["results_root"])
    rows = [(r.run_name, r.state) for r in status(plan, *roots)]
    assert rows == [
        ("dual_attention-easy-aux-s0-smoke", "to do"),
        ("dual_attention-easy-aux-sentmean-s0-smoke", "to do"),
    ]
    run_campaign(plan, *roots, jobs=1, log=lambda m: None, train_fn=fake_train)
    assert sorted(c[0] for c in calls(tracking)) == [name for name, _ in rows]
    assert (Path(tracking["run_root"]) / "eqa_readout" / "dual_attention-easy-aux-sentmean-s0-smoke").is_dir()
    (campaigns / "bad.toml").write_text('[[steps]]\nname = "a"\ntable = "experiments/nope"\nprofile = "smoke"\n')
    from emml.config.paths import REPRODUCE_DIR

    experiments = sorted(f"experiments/{f.stem}" for f in (REPRODUCE_DIR / "experiments").glob("*.toml"))
    allowed = "allowed: table2, table3, table4, table5, " + ", ".join(experiments)  # every experiment file, by name
    with pytest.raises(ValueError, match=f"table='experiments/nope' is unknown; {allowed}$"):
        load_campaign("bad", campaigns)


def test_the_pinned_worktree_holds_the_commit_and_is_made_once(tmp_path):
    def git(*args):
        subprocess.run(["git", *args], cwd=tmp_path, check=True, capture_output=True)

    git("init", "-q")
    (tmp_path / "pyproject.toml").write_text("[project]\nname='x'\n")
    git("add", "pyproject.toml")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "one")
    said = []
    tree = pin_worktree(tmp_path, log=said.append)
    assert (tree / "pyproject.toml").exists() and said == []
    (tmp_path / "pyproject.toml").write_text("[project]\nname='y'\n")  # an edit after the pin
    assert pin_worktree(tmp_path, log=said.append) == tree
    assert "name='x'" in (tree / "pyproject.toml").read_text()
    assert said and "uncommitted changes" in said[0]


def test_cli_status_and_an_unknown_campaign(tracking):
    import json

    from typer.testing import CliRunner

    from emml.cli import app

    runner = CliRunner()
    result = runner.invoke(app, ["campaign", "nope", "--status"])
    assert result.exit_code == 2 and "known campaigns: reference" in result.output
    roots = ["--run-root", tracking["run_root"], "--results-root", tracking["results_root"]]
    result = runner.invoke(app, ["campaign", "reference", "--status", *roots])
    assert result.exit_code == 0, result.output
    assert "table2-aux-s0 (table2 [quick]): 0/7 done" in result.output and "to do" in result.output
    # each step: its claims, and its cost here and on a GPU node (8 quick runs side by side at NODE_FPS)
    assert "  decides: da-best-hard-aux" in result.output
    assert "table5-house-s0 (table5 [quick]): 0/2 done" in result.output
    assert f"~{5_000_192 / 360 / 60:.0f} min of a GPU node (8 at a time" in result.output
    rows = json.loads(runner.invoke(app, ["campaign", "reference", "--status", "--json", *roots]).output)
    assert rows[0]["run_name"] == "concat-easy-aux-s0-quick" and rows[0]["state"] == "to do"
    # issue 63: `emml campaign status NAME`, the flag kept as its alias; anything else in status's place is refused
    assert runner.invoke(app, ["campaign", "status", "reference", *roots]).output == result.output
    result = runner.invoke(app, ["campaign", "reference", "status", *roots])
    assert result.exit_code == 2
    assert "expected `emml campaign run NAME` or `emml campaign status NAME`" in result.output


def test_a_pinned_campaign_runs_the_worktrees_code_into_the_checkouts_roots(tmp_path, campaign_lock, monkeypatch):
    """(`campaign_lock`: a lock of its own, so that a campaign training in this checkout does not refuse the test.)"""
    import os

    from typer.testing import CliRunner

    import emml.experiments.campaign
    from emml.cli import app
    from emml.config.paths import project_path

    monkeypatch.chdir(os.getcwd())  # restored after the test: the command changes directory before it execs
    tree = tmp_path / "tree"
    tree.mkdir()
    monkeypatch.setattr(emml.experiments.campaign.run, "pin_worktree", lambda root, log, need: tree)
    seen = {}

    def execve(path, args, env):
        seen.update(cwd=os.getcwd(), args=args, env=env)
        raise SystemExit(0)

    monkeypatch.setattr(os, "execve", execve)
    result = CliRunner().invoke(app, ["campaign", "reference"])
    assert result.exit_code == 0, result.output
    assert seen["cwd"] == str(tree) and seen["env"]["PYTHONPATH"] == str(tree)  # `-m` reads the cwd first
    args = seen["args"]
    # no roots given: none passed, the tree resolves each step's profile's own under this checkout
    # (emml.config.paths.checkout_root; tests/config/test_paths.py), smoke under scratch/
    assert "--run-root" not in args and "--results-root" not in args
    assert "--no-pin" in args and seen["env"]["MLFLOW_TRACKING_URI"]
    result = CliRunner().invoke(app, ["campaign", "reference", "--run-root", "elsewhere/runs"])
    args = seen["args"]
    assert result.exit_code == 0 and args[args.index("--run-root") + 1] == str(project_path("elsewhere/runs"))


def test_wall_time_fills_each_steps_slots_in_order_and_steps_follow_each_other():
    from emml.experiments.campaign import RunStatus, wall_seconds

    def run(step, seconds, state="to do"):
        return RunStatus(
            step, "table2", "quick", f"{step}-{seconds}", state, 0, 100, None, seconds, seconds and 2 * seconds
        )

    rows = [run("a", 10.0), run("a", 20.0), run("a", 5.0), run("a", 99.0, "done"), run("b", 7.0), run("b", None)]
    assert wall_seconds(rows, 1) == 10 + 20 + 5 + 7  # one at a time: the sum; done and unmeasured runs count 0
    assert wall_seconds(rows, 2) == 20 + 7  # a: 10 then 5 beside 20; b: alone, after a's last run
    assert wall_seconds(rows, 8) == 20 + 7
    assert wall_seconds(rows, 8, node=True) == 2 * (20 + 7)  # from the GPU-node estimates


def test_cli_status_says_how_many_runs_at_a_time_and_refuses_a_device_by_name(tracking):
    from typer.testing import CliRunner

    from emml.cli import app

    runner = CliRunner()
    roots = ["--run-root", tracking["run_root"], "--results-root", tracking["results_root"]]
    result = runner.invoke(app, ["campaign", "reference", "--status", "--jobs", "1", *roots])
    assert result.exit_code == 0 and "(one at a time;" in result.output, result.output
    result = runner.invoke(app, ["campaign", "reference", "--status", "--jobs", "8", "--device", "cuda", *roots])
    assert result.exit_code == 0 and "with 8 runs at a time on cuda" in result.output, result.output
    result = runner.invoke(
        app, ["campaign", "reference", "--status", "--device", "tpu", *roots], env={"COLUMNS": "200"}
    )
    assert result.exit_code == 2 and "'tpu' is not one of 'cpu', 'cuda'" in result.output, result.output


def test_steps_can_be_chosen_by_name_in_the_campaigns_order(tracking, campaigns):
    from emml.experiments.campaign import select_steps

    plan = load_campaign("mine", campaigns)
    assert select_steps(plan, []) is plan
    assert [s.name for s in select_steps(plan, ["second", "first"]).steps] == ["first", "second"]
    second = select_steps(plan, ["second"])
    roots = (tracking["run_root"], tracking["results_root"])
    assert [r.run_name for r in status(second, *roots)] == ["ga-easy-aux-s0-smoke", "ga-easy-noaux-warm400000-s0-smoke"]
    run_campaign(second, *roots, jobs=1, log=lambda m: None, train_fn=fake_train)
    assert [c[0] for c in calls(tracking)] == [
        "ga-easy-aux-s0-smoke",
        "ga-easy-noaux-warm400000-s0-smoke",
    ]  # not "first"'s
    with pytest.raises(ValueError, match=r"step='thrid' is not a step of campaign 'mine'; allowed: first, second"):
        select_steps(plan, ["first", "thrid"])


def test_cli_step_filters_the_status_and_travels_to_the_pinned_worktree(tracking, tmp_path, campaign_lock, monkeypatch):
    import os

    from typer.testing import CliRunner

    import emml.experiments.campaign
    from emml.cli import app

    runner = CliRunner()
    roots = ["--run-root", tracking["run_root"], "--results-root", tracking["results_root"]]
    result = runner.invoke(app, ["campaign", "reference", "--status", "--step", "table2-noaux-s0", *roots])
    assert result.exit_code == 0, result.output
    assert "table2-noaux-s0 (table2 [quick]): 0/7 done" in result.output and "table2-aux-s0" not in result.output
    result = runner.invoke(app, ["campaign", "reference", "--status", "--step", "nope", *roots])
    assert result.exit_code == 2 and "step='nope' is not a step of campaign 'reference'" in result.output
    monkeypatch.chdir(os.getcwd())
    monkeypatch.setattr(emml.experiments.campaign.run, "pin_worktree", lambda root, log, need: tmp_path)
    seen = {}

    def execve(path, args, env):
        seen.update(args=args)
        raise SystemExit(0)

    monkeypatch.setattr(os, "execve", execve)
    result = runner.invoke(app, ["campaign", "reference", "--step", "table3-noaux-s0", "--step", "table2-noaux-s0"])
    assert result.exit_code == 0, result.output
    args = seen["args"]
    assert [args[i + 1] for i, a in enumerate(args) if a == "--step"] == ["table3-noaux-s0", "table2-noaux-s0"]


def _repo(path: Path) -> Path:
    def git(*args):
        subprocess.run(["git", *args], cwd=path, check=True, capture_output=True)

    git("init", "-q")
    (path / "pyproject.toml").write_text("[project]\nname='x'\n")
    git("add", "pyproject.toml")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "one")
    return path


def test_a_campaign_file_not_committed_is_refused_saying_to_commit_it(tmp_path):
    root = _repo(tmp_path)
    mine = root / "reproduce" / "campaigns" / "mine.toml"
    mine.parent.mkdir(parents=True)
    mine.write_text(CAMPAIGN)
    with pytest.raises(ValueError, match=r"^reproduce/campaigns/mine.toml is not committed: .* commit it \(git add"):
        pin_worktree(root, log=lambda m: None, need=mine)
    assert not (root / ".campaign").exists() or not any((root / ".campaign").glob("*/pyproject.toml"))


def test_concurrent_pins_make_one_worktree_and_a_half_made_one_is_made_again(tmp_path):
    from concurrent.futures import ThreadPoolExecutor

    root = _repo(tmp_path)
    with ThreadPoolExecutor(4) as pool:  # issue 54: the second start died in a `git worktree add` traceback
        trees = set(pool.map(lambda _: pin_worktree(root, log=lambda m: None), range(4)))
    (tree,) = trees
    assert (tree / "pyproject.toml").exists()
    shutil.rmtree(tree)
    tree.mkdir()  # a start killed in the middle of `git worktree add`
    (tree / "partial").write_text("")
    assert pin_worktree(root, log=lambda m: None) == tree and (tree / "pyproject.toml").exists()


@pytest.fixture
def campaign_lock(tmp_path, monkeypatch):
    import emml.experiments.campaign

    path = tmp_path / "lock" / "campaign.lock"
    monkeypatch.setattr(emml.experiments.campaign.lock, "campaign_lock_path", lambda: path)
    return path


def test_one_campaign_per_checkout_the_second_is_refused_naming_the_first(tracking, campaign_lock, monkeypatch):
    import os

    from typer.testing import CliRunner

    import emml.experiments.campaign
    from emml.cli import app
    from emml.experiments.campaign import CampaignRunning, hold_campaign

    def never(*a, **k):
        raise AssertionError("nothing may start")

    monkeypatch.setattr(emml.experiments.campaign, "run_campaign", never)
    monkeypatch.setattr(emml.experiments.campaign.run, "pin_worktree", never)
    roots = ["--run-root", tracking["run_root"], "--results-root", tracking["results_root"]]
    with hold_campaign("reference"):
        with pytest.raises(
            CampaignRunning, match=rf"campaign 'reference' is already training into .*: pid {os.getpid()}"
        ):
            with hold_campaign("reference"):
                pass
        for pin in ("--pin", "--no-pin"):  # pinned: refused before a worktree is made; unpinned: before it trains
            result = CliRunner().invoke(app, ["campaign", "reference", pin, "--jobs", "1", *roots])
            assert result.exit_code == 2 and result.output.count("\n") == 1, result.output
            assert f"pid {os.getpid()} on host" in result.output and "one campaign per checkout" in result.output
        status = CliRunner().invoke(app, ["campaign", "reference", "--status", "--jobs", "1", *roots])
        assert status.exit_code == 0, status.output  # --status reads, beside a running campaign
    with hold_campaign("reference"):  # released with its holder
        pass


def test_the_resume_line_repeats_every_option_that_changes_what_is_resumed(tracking, campaign_lock, monkeypatch):
    import shlex

    from typer.testing import CliRunner

    import emml.experiments.campaign
    from emml.cli import app
    from emml.config.paths import project_path
    from emml.experiments.launch import LaunchReport

    seen = {}

    def stopped(plan, run_root, results_root, device, jobs, log):
        seen.update(run_root=run_root, results_root=results_root, jobs=jobs, steps=[s.name for s in plan.steps])
        return [LaunchReport("table2", "quick", "local", stopped="Ctrl-C", unfinished=["x"])]

    monkeypatch.setattr(emml.experiments.campaign, "run_campaign", stopped)
    args = ["--step", "table2-noaux-s0", "--jobs", "3", "--run-root", tracking["run_root"]]
    args += ["--results-root", tracking["results_root"], "--no-pin"]
    result = CliRunner().invoke(app, ["campaign", "reference", *args])
    assert result.exit_code == 130, result.output
    again = shlex.split(result.output.strip().split("resume with: ", 1)[1])
    assert again[:4] == ["emml", "campaign", "run", "reference"] and sorted(again[4:]) == sorted(args)
    assert project_path(tracking["run_root"]) == project_path(again[again.index("--run-root") + 1])
    # issue 54: without the roots, the resumed campaign started new runs under the default ones
    assert seen == {"run_root": tracking["run_root"], "results_root": tracking["results_root"], "jobs": 3,
                    "steps": ["table2-noaux-s0"]}  # fmt: skip


def test_status_names_a_damaged_run_dir_or_results_csv_and_goes_on(tracking, campaigns, capsys):
    plan = load_campaign("mine", campaigns)
    roots = (tracking["run_root"], tracking["results_root"])
    torn = Path(tracking["run_root"]) / "table2" / "ga-easy-aux-s0-smoke" / "metrics.csv"
    torn.parent.mkdir(parents=True)
    torn.write_text("step,key,value\n64,charts/fps,100.0\n128,charts/fps,10")  # a live run writing, or a kill
    garbage = Path(tracking["run_root"]) / "table2" / "ga-easy-noaux-warm400000-s0-smoke" / "metrics.csv"
    garbage.parent.mkdir(parents=True)
    garbage.write_text("step,key,value\n64,charts/fps,100.0\n\x00\x00garbage\n128,charts/fps,100.0\n")
    for mirror in (torn, garbage):  # interrupted runs: a checkpoint to resume from
        (mirror.parent / "checkpoint.pt").write_bytes(b"")
    rows = {r.run_name: r for r in status(plan, *roots)}
    assert rows["ga-easy-aux-s0-smoke"].frames == 64 and rows["ga-easy-noaux-warm400000-s0-smoke"].frames == 128
    err = capsys.readouterr().err
    assert f"note: {garbage}: a line near its end is not a metric point" in err and str(torn) not in err
    assert torn.read_text().endswith(",10")  # a reader never cuts a file a live run may be writing
    csv = Path(tracking["results_root"]) / "table3" / "smoke.csv"
    csv.parent.mkdir(parents=True)
    csv.write_text("run_name,seed\nx,notanint\n")
    with pytest.raises(CannotCount) as refused:  # issue 85: left out, its steps counted as no run (a wrong total)
        status(plan, *roots)
    assert f"{csv}: line 2: column 'seed'" in str(refused.value) and "cannot count" in str(refused.value)


def test_cli_status_with_a_damaged_results_row_says_it_cannot_count(tracking):
    """Issue 85: one garbage line in a results CSV showed its steps '0/0 done' and a total of 3 runs left (of 78);
    now --status refuses to count, naming the file and the line, exit 2, no traceback."""
    from typer.testing import CliRunner

    from emml.cli import app

    csv = Path(tracking["results_root"]) / "table2" / "quick.csv"
    csv.parent.mkdir(parents=True)
    csv.write_text("run_name,seed,frames\nconcat-easy-aux-s0-quick,0,1500160\n\x00garbage,,\n")
    roots = ["--run-root", tracking["run_root"], "--results-root", tracking["results_root"]]
    result = CliRunner().invoke(app, ["campaign", "reference", "--status", "--jobs", "1", *roots])
    assert result.exit_code == 2, result.output  # the CLI's refusal (`_fail`)
    assert f"{csv}: line 3" in result.output and "cannot count" in result.output, result.output
    assert "left:" not in result.output and "done" not in result.output and "Traceback" not in result.output


def test_cli_status_of_the_reference_campaign_names_a_garbage_mirror_and_goes_on(tracking):
    from typer.testing import CliRunner

    from emml.cli import app

    mirror = Path(tracking["run_root"]) / "table2" / "concat-easy-aux-s0-quick" / "metrics.csv"
    mirror.parent.mkdir(parents=True)
    mirror.write_text("step,key,value\n1024,charts/fps,50.0\nnot,a,number\n2048,charts/fps,5")
    roots = ["--run-root", tracking["run_root"], "--results-root", tracking["results_root"]]
    result = CliRunner().invoke(app, ["campaign", "reference", "--status", "--jobs", "1", *roots])
    assert result.exit_code == 0, result.output  # issue 54: a ValueError traceback
    assert f"{mirror}: line 3: not a metric point" in result.output
    assert "concat-easy-aux-s0-quick" in result.output
