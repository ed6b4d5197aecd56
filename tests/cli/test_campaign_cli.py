"""`emml campaign run NAME` and `emml campaign status NAME`, and the deprecated `emml campaign NAME [--status]`
read as them (the spelling a stopped campaign's resume line, a pinned re-execution and scripts/gpu-campaign use)."""

from __future__ import annotations

import os

import pytest
import typer
from typer.testing import CliRunner

from emml.cli import app
from emml.cli.campaign import legacy_args

runner = CliRunner()
COMMANDS = ("run", "status")


@pytest.mark.parametrize(
    "args, read_as",
    [
        (["reference"], ["run", "reference"]),
        (["reference", "--no-pin", "--jobs", "2"], ["run", "reference", "--no-pin", "--jobs", "2"]),
        (["--jobs", "2", "reference"], ["run", "--jobs", "2", "reference"]),
        (["reference", "--status", "--json"], ["status", "reference", "--json"]),
        (["reference", "--no-pin", "--status", "--pin"], ["status", "reference"]),  # status takes no --pin
        (["run", "reference"], ["run", "reference"]),
        (["status", "reference", "--json"], ["status", "reference", "--json"]),
        (["--help"], ["--help"]),
        ([], []),
    ],
)
def test_the_deprecated_spelling_is_read_as_the_subcommands(args, read_as):
    assert legacy_args(list(args), COMMANDS) == read_as


def test_the_status_word_after_the_name_is_refused_naming_both_spellings():
    with pytest.raises(typer.Exit):
        legacy_args(["reference", "status"], COMMANDS)
    result = runner.invoke(app, ["campaign", "reference", "status"])
    assert result.exit_code == 2
    assert "expected `emml campaign run NAME` or `emml campaign status NAME`" in result.output, result.output


def test_campaign_help_lists_run_and_status_and_names_the_old_spelling_deprecated():
    result = runner.invoke(app, ["campaign", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert "run " in result.output and "status " in result.output and "deprecated" in result.output
    assert runner.invoke(app, ["campaign", "status", "--help"]).exit_code == 0
    # status trains nothing: it takes no --pin, and run has no --status
    assert runner.invoke(app, ["campaign", "status", "reference", "--no-pin"]).exit_code == 2
    result = runner.invoke(app, ["campaign", "run", "reference", "--status"])
    assert result.exit_code == 2 and "No such option" in result.output, result.output


def test_campaign_status_shows_the_runs_and_the_old_spelling_says_the_same(tracking):
    import json

    roots = ["--run-root", tracking["run_root"], "--results-root", tracking["results_root"]]
    result = runner.invoke(app, ["campaign", "status", "reference", *roots])
    assert result.exit_code == 0, result.output
    assert "table2-aux-s0 (table2 [quick]): 0/7 done" in result.output and "to do" in result.output
    assert runner.invoke(app, ["campaign", "reference", "--status", *roots]).output == result.output
    only = runner.invoke(app, ["campaign", "status", "reference", "--step", "table5-house-s0", "--json", *roots])
    assert only.exit_code == 0, only.output
    assert {row["step"] for row in json.loads(only.stdout)} == {"table5-house-s0"}
    unknown = runner.invoke(app, ["campaign", "status", "nope"])
    assert unknown.exit_code == 2 and "known campaigns: reference" in unknown.output


@pytest.fixture
def no_lock(tmp_path, monkeypatch):
    """A campaign lock of the test's own: a campaign training in this checkout does not refuse the test."""
    import emml.experiments.campaign

    monkeypatch.setattr(emml.experiments.campaign.lock, "campaign_lock_path", lambda: tmp_path / "campaign.lock")


def test_campaign_run_pins_a_worktree_and_the_old_spelling_runs_the_same(tmp_path, no_lock, monkeypatch):
    import emml.experiments.campaign

    monkeypatch.chdir(os.getcwd())  # the command changes directory before it execs
    monkeypatch.setattr(emml.experiments.campaign.run, "pin_worktree", lambda root, log, need: tmp_path)
    execs = []

    def execve(path, args, env):
        execs.append(args)
        raise SystemExit(0)

    monkeypatch.setattr(os, "execve", execve)
    for words in (["campaign", "run", "reference"], ["campaign", "reference"]):
        result = runner.invoke(app, [*words, "--jobs", "2", "--step", "table5-house-s0"])
        assert result.exit_code == 0, result.output
    new, old = execs
    assert new == old and "--no-pin" in new and new[new.index("--step") + 1] == "table5-house-s0"


def test_campaign_run_no_pin_trains_the_steps_here(no_lock, monkeypatch):
    import emml.cli.campaign
    import emml.experiments.campaign

    plans = []
    monkeypatch.setattr(emml.cli.campaign, "_use_tcmalloc", lambda: None)  # no re-exec of the test process
    monkeypatch.setattr(emml.experiments.campaign, "run_campaign", lambda plan, *a, **k: plans.append(plan) or [])
    for words in (["campaign", "run", "reference"], ["campaign", "reference"]):
        result = runner.invoke(app, [*words, "--no-pin", "--step", "table5-house-s0"])
        assert result.exit_code == 0, result.output
        assert "reference: 0 trained, 0 already finished, 0 failed" in result.output
    assert [[s.name for s in plan.steps] for plan in plans] == [["table5-house-s0"]] * 2
