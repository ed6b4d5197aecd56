"""Names on the command line: the shell completes tables, campaigns, steps and models from where the project declares
them (reproduce/*.toml, reproduce/campaigns/*.toml, the model registry), and a misspelled `--set` field or model
is refused before any compute naming the closest allowed names."""

from __future__ import annotations

import functools

import pytest
from typer.testing import CliRunner

from emml.cli import app

runner = CliRunner()


def complete(line: str) -> list[str]:
    """What `emml` answers the shell completing ``line`` (bash; the last word is the one being typed)."""
    words = line.split(" ")
    env = {"_EMML_COMPLETE": "complete_bash", "COMP_WORDS": line, "COMP_CWORD": str(len(words) - 1)}
    result = runner.invoke(app, [], prog_name="emml", env=env)
    assert result.exit_code == 0, result.output
    return result.output.split()


@pytest.fixture
def declared(tmp_path, monkeypatch):
    """A reproduce/ of the test's own: tables table7 and table9, the experiment my_exp, campaigns alpha and beta."""
    import emml.experiments.campaign.file as campaign_file
    import emml.experiments.table_files as table_files

    for name in ("table7.toml", "table9.toml", "profiles.toml", "experiments/my_exp.toml", "campaigns/alpha.toml"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("")
    (tmp_path / "campaigns" / "beta.toml").write_text("")
    monkeypatch.setattr(table_files, "list_tables", functools.partial(table_files.list_tables, tmp_path))
    experiments = functools.partial(table_files.list_experiments, tmp_path / "experiments")
    monkeypatch.setattr(table_files, "list_experiments", experiments)
    campaigns = functools.partial(campaign_file.list_campaigns, tmp_path / "campaigns")
    monkeypatch.setattr(campaign_file, "list_campaigns", campaigns)


def test_table_and_campaign_names_are_completed_from_their_files(declared):
    assert complete("emml run ") == ["table7", "table9", "experiments/my_exp"]
    assert complete("emml run experiments/") == ["experiments/my_exp"]
    assert complete("emml report table9") == ["table9"]
    assert complete("emml campaign run ") == ["alpha", "beta"]
    assert complete("emml campaign status b") == ["beta"]
    assert complete("emml campaign a") == []  # the deprecated spelling is not offered: the subcommands are
    assert complete("emml campaign ") == ["run", "status"]


def test_the_projects_own_tables_campaigns_and_steps_are_completed():
    from emml.config.paths import REPRODUCE_DIR
    from emml.experiments.campaign import load_campaign

    assert complete("emml run table") == sorted(p.stem for p in REPRODUCE_DIR.glob("table*.toml"))
    assert complete("emml campaign run ") == sorted(p.stem for p in (REPRODUCE_DIR / "campaigns").glob("*.toml"))
    settle = [s.name for s in load_campaign("reference").steps if s.name.startswith("settle-")]
    assert settle and complete("emml campaign run reference --step settle-") == settle
    assert complete("emml campaign status reference --jobs 2 --step settle-") == settle
    assert complete("emml campaign reference --step settle-") == settle  # the deprecated spelling too
    assert complete("emml campaign run --step settle-") == []  # no campaign named yet


def test_model_names_are_completed_from_the_registry(monkeypatch):
    from emml.models import registry

    assert complete("emml train --model ") == list(registry.MODELS)
    monkeypatch.setitem(registry._ENTRIES, "zz_mine", registry.MODELS["concat"])  # as a plugin registers one
    assert complete("emml train --model zz") == ["zz_mine"]
    assert complete("emml bench train --model zz") == ["zz_mine"]


@pytest.fixture
def nothing_trains(monkeypatch):
    import emml.rl.trainer

    monkeypatch.setattr(emml.rl.trainer, "train", lambda *a, **k: pytest.fail("trained"))


@pytest.mark.parametrize(
    "option, close",
    [
        ("env.heigth=60", "did you mean 'env.height'?"),
        ("fraems=512", "did you mean 'frames'"),
        ("lr=1e-4", "did you mean 'ppo.lr'?"),  # the section left out
        ("ppo.entropy_coef=0.1", "did you mean 'ppo.ent_coef'"),
        ("envv.height=60", "did you mean 'env.height'"),  # a misspelled section
    ],
)
def test_a_misspelled_set_field_names_the_closest_before_any_compute(option, close, tmp_path, nothing_trains):
    args = ["train", "--profile", "smoke", "--set", option, "--set", f'run_root="{tmp_path}"']
    result = runner.invoke(app, args, env={"COLUMNS": "200"})
    assert result.exit_code == 2 and close in result.output, result.output
    field = option.split("=")[0]
    assert f"--set '{field}'" in result.output and ("known:" in result.output or "not one of" in result.output)
    assert list(tmp_path.iterdir()) == []


def test_a_set_field_close_to_none_gets_no_guess(tmp_path, nothing_trains):
    result = runner.invoke(app, ["train", "--profile", "smoke", "--set", "zzzz=1", "--set", f'run_root="{tmp_path}"'])
    assert result.exit_code == 2 and "--set 'zzzz': unknown field; known: model, aux" in result.output
    assert "did you mean" not in result.output


@pytest.mark.parametrize(
    "args, option, close",
    [
        (["train", "--model", "dual_atention"], "--model", "did you mean 'dual_attention'?"),
        (["bench", "train", "--model", "concatt"], "--model", "did you mean 'concat'?"),
        (["train", "--profile", "quik"], "--profile", "did you mean 'quick'?"),
    ],
)
def test_a_misspelled_model_or_profile_names_the_closest_and_the_allowed(args, option, close, nothing_trains):
    from emml.models.registry import MODELS

    result = runner.invoke(app, args, env={"COLUMNS": "400"})
    assert result.exit_code == 2, result.output
    text = " ".join(result.output.replace("│", " ").split())  # the error box's lines joined
    assert f"Invalid value for '{option}'" in text and close in text, text
    if option == "--model":
        assert all(repr(m) in text for m in MODELS) and "--plugin" in text  # a plugin's model may be meant


def test_a_model_far_from_every_name_gets_no_guess(nothing_trains):
    result = runner.invoke(app, ["train", "--model", "xyzzy"], env={"COLUMNS": "400"})
    assert result.exit_code == 2 and "'xyzzy' is not one of" in result.output and "did you mean" not in result.output
