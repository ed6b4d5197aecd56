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
