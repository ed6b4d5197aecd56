import json

from typer.testing import CliRunner

from emml.cli import app

runner = CliRunner()


def test_tasks_show_json():
    result = runner.invoke(app, ["tasks", "show", "doom", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
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
    assert json.loads(result.output)["accuracy"] == 1.0


def test_bad_input_is_named_before_compute(no_leftovers):
    result = runner.invoke(app, ["oracle", "--difficulty", "medium"])
    assert result.exit_code == 2
    assert "difficulty='medium'" in result.output and "'easy', 'hard'" in result.output
    result = runner.invoke(app, ["tasks", "show", "house3d"])
    assert result.exit_code == 2 and "dataset='house3d'" in result.output


def test_diagnose_a_checkpoint(tracking, no_leftovers):
    from emml.profiles import profile_config
    from emml.rl.trainer import CHECKPOINT, train

    over = {"run_root": tracking["run_root"], "results_root": tracking["results_root"], "table": "test"}
    cfg = profile_config("smoke", "easy", {**over, "frames": 64, "eval_episodes": 1, "diagnose_episodes": 0}, aux=True)
    path = train(cfg, quiet=True).run_dir / CHECKPOINT
    result = runner.invoke(app, ["diagnose", str(path), "--episodes", "2", "--step0-episodes", "10", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert 0.0 <= data["attention_on_target"] <= 1.0 and 0.0 <= data["actor_sensitivity"] <= 1.0
    assert all(0.0 <= ap <= 1.0 for ap in data["detector_ap_words"].values())
    text = runner.invoke(app, ["diagnose", str(path), "--episodes", "1", "--step0-episodes", "5"])
    assert text.exit_code == 0 and "detector AP per word" in text.output and "slot" in text.output
    missing = runner.invoke(app, ["diagnose", str(path.parent / "nope.pt")])
    assert missing.exit_code == 2 and "does not exist" in missing.output
