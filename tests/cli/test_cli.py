import json

import pytest
import typer
from typer.testing import CliRunner

from emml.cli import app

runner = CliRunner()


def test_tasks_show_json():
    result = runner.invoke(app, ["tasks", "show", "doom", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert len(data["sgn_train"]) == 42 and len(data["sgn_test"]) == 28
    assert len(data["eqa_train"]) == 21 and len(data["eqa_test"]) == 8
    assert len(data["vocabulary"]) == 22 and len(data["actors"]) == 18


def test_oracle_json(no_leftovers):
    result = runner.invoke(
        app,
        [
            "oracle",
            "--difficulty",
            "easy",
            "--task",
            "sgn",
            "--episodes",
            "5",
            "--height",
            "60",
            "--width",
            "108",
            "--json",
        ],
    )
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["accuracy"] == 1.0


def test_bad_input_is_named_before_compute(no_leftovers):
    result = runner.invoke(app, ["oracle", "--difficulty", "medium"], env={"COLUMNS": "200"})
    assert result.exit_code == 2
    assert "'--difficulty'" in result.output and "'medium' is not one of 'easy', 'hard'" in result.output
    result = runner.invoke(app, ["tasks", "show", "house3d"])
    assert result.exit_code == 2 and "dataset='house3d'" in result.output


def test_diagnose_a_checkpoint(tracking, no_leftovers):
    from emml.config.profiles import profile_config
    from emml.rl.trainer import train
    from emml.runs.rundir import CHECKPOINT

    over = {"run_root": tracking["run_root"], "results_root": tracking["results_root"], "table": "test"}
    short = {"frames": 64, "eval_episodes": 1, "diagnose_episodes": 0, "env.max_steps": 12}
    cfg = profile_config("smoke", "easy", {**over, **short}, aux=True)
    path = train(cfg, quiet=True).run_dir / CHECKPOINT
    sgn = ["--episodes", "2", "--step0-episodes", "10", "--eqa-episodes", "0"]
    result = runner.invoke(app, ["diagnose", str(path), *sgn, "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert 0.0 <= data["attention_on_target"] <= 1.0 and 0.0 <= data["actor_sensitivity"] <= 1.0
    assert all(0.0 <= ap <= 1.0 for ap in data["detector_ap_words"].values())
    assert "eqa" not in data and data["control"] == "none"
    assert 0.0 <= data["x_image_saturated"] <= 1.0 and data["x_image_channels"]
    assert 0.0 <= data["conv3_one_way"] <= 1.0  # trained a few updates: its conv moved (issue 48)
    both = ["--episodes", "1", "--step0-episodes", "5", "--eqa-episodes", "1"]
    text = runner.invoke(app, ["diagnose", str(path), *both])
    assert text.exit_code == 0 and "detector AP per word" in text.output and "slot" in text.output
    assert "x_I saturation:" in text.output and "conv3 since its init:" in text.output
    assert "EQA per question" in text.output and "what color is the torch" in text.output
    no_step0 = runner.invoke(
        app, ["diagnose", str(path), "--episodes", "1", "--step0-episodes", "0", "--eqa-episodes", "0"]
    )
    assert no_step0.exit_code == 0 and "by target slot: n/a (--step0-episodes 0)" in no_step0.output  # not 'Hard'
    eqa = ["diagnose", str(path), "--episodes", "0", "--step0-episodes", "0", "--eqa-episodes", "1"]
    gated = runner.invoke(app, [*eqa, "--control", "type_gate", "--json"])
    assert gated.exit_code == 0, gated.output
    data = json.loads(gated.stdout)
    assert data["control"] == "type_gate" and len(data["eqa"]["questions"]) == 29 and "detector_ap" not in data
    bad = runner.invoke(app, [*eqa, "--control", "oracle"], env={"COLUMNS": "200"})
    assert bad.exit_code == 2 and "'oracle' is not one of" in bad.output
    scores = runner.invoke(app, ["eval", str(path), "--episodes", "1", "--control", "type_gate", "--json"])
    assert scores.exit_code == 0, scores.output
    assert set(json.loads(scores.stdout)) == {"sgn_train", "sgn_test", "eqa_train", "eqa_test"}
    missing = runner.invoke(app, ["diagnose", str(path.parent / "nope.pt")])
    assert missing.exit_code == 2 and "no such file" in missing.output


def _bad_checkpoints(tmp_path):
    import torch

    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "checkpoint.pt").write_bytes(b"")
    (tmp_path / "empty.pt").write_bytes(b"")
    (tmp_path / "garbage.pt").write_bytes(b"not a checkpoint\x00\x01" * 10)
    torch.save({"weights": 1}, tmp_path / "foreign.pt")
    return {
        "run": "is a directory, not a checkpoint file (did you mean its checkpoint.pt?)",
        "empty.pt": "is empty (0 bytes)",
        "garbage.pt": "not a PyTorch checkpoint",
        "foreign.pt": "not an emml checkpoint (missing model, config, frames)",
        "nope.pt": "no such file",
    }


def test_a_bad_checkpoint_gets_one_line_naming_it(tmp_path, no_leftovers):
    for name, why in _bad_checkpoints(tmp_path).items():
        path = tmp_path / name
        for command in (["eval", str(path), "--episodes", "1"], ["diagnose", str(path)]):
            result = runner.invoke(app, command)
            assert result.exit_code == 2, (command, result.output)
            assert result.output.strip() == f"error: checkpoint {path}: {why}" or (
                result.output.startswith(f"error: checkpoint {path}: {why}") and result.output.count("\n") == 1
            ), result.output


def test_train_over_a_bad_or_foreign_checkpoint_fails_by_name_and_keeps_it(tracking, no_leftovers):
    import torch

    from emml.config.profiles import profile_config
    from emml.runs.rundir import CHECKPOINT, run_dir

    sets = ["--set", f"run_root={tracking['run_root']}", "--set", f"results_root={tracking['results_root']}"]
    args = ["train", "--profile", "smoke", "--aux", "--table", "test", *sets]
    cfg = profile_config("smoke", "easy", {"run_root": tracking["run_root"], "table": "test"}, aux=True)
    path = run_dir(cfg) / CHECKPOINT
    path.parent.mkdir(parents=True)
    path.write_bytes(b"\x80garbage")
    result = runner.invoke(app, args)
    assert result.exit_code == 2 and result.output.startswith(f"error: checkpoint {path}: not a PyTorch checkpoint")
    assert "Traceback" not in result.output and path.read_bytes() == b"\x80garbage"
    torch.save({"model": {}, "config": {**cfg.to_dict(), "seed": 7}, "frames": 64}, path)
    result = runner.invoke(app, args)
    assert result.exit_code == 2 and result.output.count("\n") <= 2, result.output
    assert "holds a run with a different config (" in result.output and "seed)" in result.output
    import mlflow

    assert mlflow.search_runs(search_all_experiments=True).empty  # nothing started, nothing recorded


def test_house_tasks_and_oracle_json(no_leftovers):
    result = runner.invoke(app, ["tasks", "show", "house", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert len(data["sgn_train"]) == 22 and len(data["sgn_test"]) == 11
    assert len(data["eqa_train"]) == 8 and len(data["eqa_test"]) == 2 and len(data["actors"]) == 24
    args = ["oracle", "--env", "house", "--task", "sgn", "--episodes", "3", "--height", "60", "--width", "108"]
    result = runner.invoke(app, [*args, "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["env"] == "house" and data["accuracy"] == 1.0
    result = runner.invoke(app, ["oracle", "--env", "attic"], env={"COLUMNS": "200"})
    assert result.exit_code == 2 and "'attic' is not one of 'doom', 'house'" in result.output


def test_train_on_a_full_disk_fails_in_one_line_and_its_mlflow_run_ends_failed(tracking, monkeypatch, no_leftovers):
    """The first checkpoint is written once the MLflow run exists, before any engine starts: a full disk there names
    the folder in one line, leaves no temp file, and ends the run FAILED (it stayed RUNNING forever)."""
    import errno

    import mlflow

    from emml.config.profiles import profile_config
    from emml.runs import checkpoint
    from emml.runs.rundir import CHECKPOINT, run_dir

    def fills_the_disk(payload, fh):
        fh.write(b"half a checkpoint")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(checkpoint.torch, "save", fills_the_disk)
    sets = ["--set", f"run_root={tracking['run_root']}", "--set", f"results_root={tracking['results_root']}"]
    result = runner.invoke(app, ["train", "--profile", "smoke", "--table", "test", *sets])
    folder = run_dir(profile_config("smoke", "easy", {"run_root": tracking["run_root"], "table": "test"}))
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output  # above the error: at most MLflow's log lines creating the store
    assert result.output.splitlines()[-1] == (
        f"error: no space left on {folder} (writing {CHECKPOINT}, left as it was): free some space and rerun the "
        "same command to resume from the last checkpoint"
    )
    assert not [p for p in folder.iterdir() if p.name.endswith(".tmp") or p.name == CHECKPOINT]
    (run,) = mlflow.search_runs(experiment_names=["test"], output_format="list")
    assert run.info.status == "FAILED"


def test_a_stopped_run_prints_a_resume_command_the_shell_reads_back(monkeypatch):
    """The resume line of a stopped `emml run` quotes each --only value: a row label has spaces."""
    import shlex

    import emml.experiments.launch
    from emml.experiments.launch import LaunchReport

    def stopped(table, profile, **kwargs):
        return LaunchReport(table=table, profile=profile, backend="local", total=1, stopped="signal SIGTERM")

    monkeypatch.setattr(emml.experiments.launch, "run_table", stopped)
    result = runner.invoke(app, ["run", "table3", "--only", "row=w/o Reward Shaping", "--only", "seed=0"])
    assert result.exit_code == 130, result.output
    again = result.output.split("resume with: ", 1)[1].strip()
    argv = ["emml", "run", "table3", "--profile", "quick", "--only", "row=w/o Reward Shaping", "--only", "seed=0"]
    assert shlex.split(again) == argv
    result = runner.invoke(app, ["run", "table3", "--jobs", "3"])  # issue 54: how many at a time, kept
    assert shlex.split(result.output.split("resume with: ", 1)[1]) == [*argv[:5], "--jobs", "3"]


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    """A finished smoke run (64 frames) in its own MLflow store: the checkpoint the commands below are given."""
    from emml.config.profiles import profile_config
    from emml.rl.trainer import train

    root = tmp_path_factory.mktemp("yield")
    uri = f"sqlite:///{root}/mlflow.db"
    over = {"run_root": str(root / "runs"), "results_root": str(root / "results"), "table": "test"}
    short = {"frames": 64, "eval_episodes": 1, "final_eval_episodes": 1, "diagnose_episodes": 0}
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("MLFLOW_TRACKING_URI", uri)
        cfg = profile_config("smoke", "easy", {**over, **short, "env.max_steps": 12}, aux=True)
        run_dir = train(cfg, quiet=True).run_dir
    return {"uri": uri, "run_dir": run_dir}


class _Played(Exception):
    """Raised where a command starts its first ViZDoom engine (or writes the reports): the test has seen what came
    before, and nothing is played or written."""


@pytest.mark.parametrize(
    "command",
    [
        ["oracle", "--episodes", "1", "--height", "60", "--width", "108"],
        ["eval", "{ckpt}", "--episodes", "1"],
        ["rescore", "{run}", "--episodes", "1", "--no-record", "--force"],
        ["transfer", "{ckpt}", "--episodes", "1"],
        ["diagnose", "{ckpt}", "--episodes", "1", "--step0-episodes", "1", "--eqa-episodes", "0"],
        ["probe-eqa", "{ckpt}", "--episodes", "1", "--seeds", "1", "--steps", "1"],
        ["video", "{ckpt}", "--episodes", "1", "--out", "{out}"],
        ["reports", "--out", "{out}"],
        ["visualize", "channels", "{ckpt}", "--out", "{out}"],
        ["visualize", "attention", "{ckpt}", "--out", "{out}"],
        ["visualize", "house", "--out", "{out}"],
    ],
    ids=lambda c: " ".join(w for w in c if not w.startswith(("-", "{")) and not w.isdigit())[:30],
)
def test_commands_that_train_nothing_yield_the_cpu_to_trainings(command, finished_run, tmp_path, monkeypatch):
    """Each command that plays or scores a model beside a training defers to it (tests/rl/test_contention.py:
    lowest priority, one thread), after its inputs are checked and before it plays: observed with a learner made
    up beside it (pid 4242), the CPU yield and torch's threads recorded instead of done, and the first engine start
    stopped. The yield comes first, the line saying so is printed, and a bad checkpoint is refused with no yield."""
    import emml.envs.engine
    import emml.report.index
    import emml.rl.contention

    events = []

    def start_engine(*args, **kwargs):  # where the command starts to play (`reports`: where it starts to write)
        events.append("engine")
        raise _Played

    monkeypatch.setenv("MLFLOW_TRACKING_URI", finished_run["uri"])
    monkeypatch.setattr(emml.rl.contention, "other_learners", lambda *a, **k: [4242])
    monkeypatch.setattr(emml.rl.contention, "_yielded", lambda: False)
    monkeypatch.setattr(emml.rl.contention, "yield_cpu", lambda: events.append("yield") or "SCHED_IDLE")
    monkeypatch.setattr("torch.set_num_threads", lambda n: events.append(f"threads {n}"))
    monkeypatch.setattr(emml.envs.engine, "start_engine", start_engine)
    monkeypatch.setattr(emml.report.index, "write_reports", start_engine)
    paths = {"ckpt": str(finished_run["run_dir"] / "checkpoint.pt"), "run": str(finished_run["run_dir"])}
    args = [a.format(**paths, out=tmp_path / "out") for a in command]
    result = runner.invoke(app, args)
    assert events[:2] == ["yield", "threads 1"], (events, result.output)  # before any engine started
    assert "1 emml learner(s) running (pid 4242)" in result.output
    if "{ckpt}" in command or "{run}" in command:  # a checkpoint that is not one: refused before any yield
        events.clear()
        missing = str(tmp_path / "nothing" / "checkpoint.pt")
        bad = runner.invoke(app, [missing if a in ("{ckpt}", "{run}") else a.format(out=tmp_path) for a in command])
        assert bad.exit_code != 0 and not isinstance(bad.exception, _Played) and events == [], (events, bad.output)


def test_a_piped_train_log_has_lines_and_no_progress_bar(tracking, no_leftovers):
    """stderr not a terminal: no tqdm frames ('\\r'), one parseable line per log_every instead, saying the tasks
    the run plays (an SGN-only run: no 'eqa') and the time left."""
    import os
    import re
    import subprocess
    import sys

    sets = {
        "run_root": tracking["run_root"],
        "results_root": tracking["results_root"],
        "frames": 128,
        "log_every": 1,
        "eval_every": 0,
        "eval_episodes": 1,
        "final_eval_episodes": 1,
        "diagnose_episodes": 0,
        "env.tasks": "sgn",  # unquoted: a bare word is a string
    }
    args = [a for k, v in sets.items() for a in ("--set", f"{k}={v}")]
    out = subprocess.run(
        [sys.executable, "-m", "emml", "train", "--profile", "smoke", "--table", "test", *args],
        capture_output=True,
        text=True,
        env={**os.environ, "EMML_MALLOC": "glibc"},
        timeout=600,
    )
    assert out.returncode == 0, out.stderr
    log = out.stdout + out.stderr
    assert "\r" not in log
    started = [x for x in log.splitlines() if x.startswith("training ")]  # said first: a bare `emml train` runs long
    root = re.escape(tracking["run_root"])
    assert len(started) == 1 and re.fullmatch(
        rf"training (\S+): 128 frames \(smoke profile, cpu\) in {root}/test/\1", started[0]
    )
    lines = [x for x in log.splitlines() if x.startswith("update ")]
    assert len(lines) == 2, log
    for line in lines:
        assert re.search(r"frames +\d[\d,]* fps +\d+ sgn (nan|\d\.\d\d) pg ", line), line
        assert " eqa " not in line and re.search(r"\| eta \d+:\d\d:\d\d$", line), line


def _commands(group, path=()):
    """(command path, click command) of every command of the app, sub-apps' included."""
    for name, cmd in group.commands.items():
        if hasattr(cmd, "commands"):
            yield from _commands(cmd, (*path, name))
        else:
            yield (*path, name), cmd


def test_help_groups_the_commands_and_says_what_every_option_does():
    import re

    from typer.main import get_command

    result = runner.invoke(app, ["--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    for panel in ("Train", "Evaluate & diagnose", "Tables & reports", "Tools", "--install-completion"):
        assert panel in result.output, panel
    internal = re.compile(r"issue \d|emml/|\.py\b|README")  # help speaks to the user, not of the code's history
    commands = dict(_commands(get_command(app)))
    assert len(commands) >= 25
    for path, cmd in commands.items():
        summary = (cmd.help or "").split("\n\n")[0]
        assert summary and "\n" not in summary.strip(), f"{path}: its summary is not one line: {summary!r}"
        assert not internal.search(cmd.help), f"{path}: {cmd.help!r}"
        for param in cmd.params:
            if param.name == "help":
                continue
            assert getattr(param, "help", None), f"emml {' '.join(path)}: {param.name} has no help"
            assert not internal.search(param.help), f"emml {' '.join(path)} {param.name}: {param.help!r}"


@pytest.mark.parametrize(
    ("args", "option", "allowed"),
    [
        (["train", "--difficulty", "medium"], "--difficulty", ("'easy'", "'hard'", "'house'")),
        (["train", "--profile", "huge"], "--profile", ("'smoke'", "'demo'", "'quick'", "'paper'")),
        (["train", "--device", "tpu"], "--device", ("'cpu'", "'cuda'")),
        (["run", "table2", "--backend", "pbs"], "--backend", ("'local'", "'slurm'")),
        (["oracle", "--task", "vqa"], "--task", ("'sgn'", "'eqa'", "'both'")),
    ],
)
def test_a_value_outside_the_choices_is_refused_naming_them(args, option, allowed, monkeypatch):
    import emml.rl.trainer

    monkeypatch.setattr(emml.rl.trainer, "train", lambda *a, **k: pytest.fail("trained"))
    result = runner.invoke(app, args, env={"COLUMNS": "200"})
    assert result.exit_code == 2, result.output
    assert f"Invalid value for '{option}'" in result.output and all(a in result.output for a in allowed)


def test_the_shell_completes_commands_and_choices():
    import os
    import subprocess
    import sys

    def complete(words: str) -> list[str]:
        env = {**os.environ, "_EMML_COMPLETE": "complete_bash", "COMP_WORDS": words, "COMP_CWORD": "3"}
        code = "from emml.cli import app; app(prog_name='emml')"
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
        return out.stdout.split()

    assert complete("emml train --difficulty ") == ["easy", "hard", "house"]
    assert complete("emml train --profile q") == ["quick"]
    assert "dual_attention" in complete("emml train --model d")


def test_set_takes_a_bare_word_as_a_string_and_toml_otherwise():
    from emml.cli.common import _parse_sets

    parsed = _parse_sets(
        [
            "env.tasks=sgn",
            "precision='bf16'",
            'env.split="test"',
            "ppo.lr=1e-4",
            "env.height=84",
            "env.shaping=false",
            'model_options={control="target_mask"}',
            "env.aux_words=['red', 'pillar']",
            "run_root=/tmp/my runs",
        ]
    )
    assert parsed == {
        "env.tasks": "sgn",
        "precision": "bf16",
        "env.split": "test",
        "ppo.lr": 1e-4,
        "env.height": 84,
        "env.shaping": False,
        "model_options": {"control": "target_mask"},
        "env.aux_words": ["red", "pillar"],
        "run_root": "/tmp/my runs",
    }
    with pytest.raises(typer.Exit):  # a table that is not TOML: refused, not taken as a string
        _parse_sets(["model_options={control=target_mask}"])


def test_train_takes_the_roots_as_options(tracking, monkeypatch):
    """--run-root and --results-root set the roots as --set run_root=... does."""
    import emml.rl.trainer
    from emml.runs.rundir import RunResult

    seen = {}

    def fake_train(cfg, quiet=False):
        seen["cfg"] = cfg
        return RunResult(run_dir=tracking["run_root"], run_id="x", frames=0, metrics={}, skipped=True)

    monkeypatch.setattr(emml.rl.trainer, "train", fake_train)
    monkeypatch.setattr("emml.cli.train._use_tcmalloc", lambda: None)
    roots = ["--run-root", tracking["run_root"], "--results-root", tracking["results_root"]]
    result = runner.invoke(app, ["train", *roots])
    assert result.exit_code == 0, result.output
    assert seen["cfg"].run_root == tracking["run_root"] and seen["cfg"].results_root == tracking["results_root"]


def test_the_slurm_path_can_be_tried_without_a_cluster_and_its_resume_line_keeps_the_jobs_shape(monkeypatch):
    """Issue 65: no option picked submitit's local executor; `--slurm-cluster local` does, and a stopped Slurm
    launch's resume line keeps the backend and the jobs' shape."""
    import shlex

    import emml.experiments.launch
    from emml.experiments.launch import LaunchReport

    seen = {}

    def stopped(table, profile, **kwargs):
        seen.update(kwargs)
        return LaunchReport(table=table, profile=profile, backend="slurm", total=1, stopped="Ctrl-C")

    monkeypatch.setattr(emml.experiments.launch, "run_table", stopped)
    args = ["run", "table3", "--backend", "slurm", "--slurm-cluster", "local", "--pack", "2", "--wait"]
    result = runner.invoke(app, args)
    assert result.exit_code == 130 and seen["slurm_cluster"] == "local" and seen["backend"] == "slurm", result.output
    again = shlex.split(result.output.split("resume with: ", 1)[1])
    assert again == ["emml", "run", "table3", "--profile", "quick", "--backend", "slurm", "--time-min", "1440",
                     "--cpus", "8", "--pack", "2", "--wait", "--slurm-cluster", "local"]  # fmt: skip
    bad = runner.invoke(app, ["run", "table3", "--backend", "slurm", "--slurm-cluster", "moon"])
    assert bad.exit_code == 2 and "moon" in bad.output


def test_a_command_without_plugins_does_not_load_the_model_zoo_before_it_runs():
    """The CLI's check for plugins reads their env var from emml/config/paths.py: without plugins to add, the
    model zoo (and torch, 4-7 s on a busy 2-core machine) is not imported before the command itself needs it."""
    import os
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from typer.testing import CliRunner\n"
        "from emml.cli import app\n"
        "r = CliRunner().invoke(app, ['campaign', 'status', 'nope'])\n"
        "print(r.exit_code, 'torch' in sys.modules, 'emml.models.plugins' in sys.modules)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "EMML_PLUGINS"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.stdout.split() == ["2", "False", "False"], out.stdout + out.stderr
