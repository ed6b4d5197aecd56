"""reproduce/profiles.toml: the committed profiles load, and a broken file is named in one line."""

import pytest
from typer.testing import CliRunner

import emml.config.profiles
from emml.cli import app
from emml.config.profiles import PROFILES_FILE, ProfileError, load_profiles, profile_config
from emml.runs.naming import run_name


def test_the_committed_profiles_load_and_keep_their_types():
    profiles = load_profiles()
    assert {"smoke", "demo", "quick", "paper"} <= set(profiles)
    cfg = profile_config("quick", "hard")
    assert cfg.frames == profiles["quick"]["frames_hard"] and cfg.env.height == 84 and cfg.num_envs == 8


@pytest.mark.parametrize(
    "text, message",
    [
        ("[smoke\nframes = 1", "not valid TOML"),
        ('[smoke]\nframes = "lots"', "[smoke] 'frames': expected an integer, got 'lots'"),
        ("[smoke]\nfraems = 512", "[smoke] 'fraems': unknown field; known: model, aux"),
        ('[smoke]\n"env.heigth" = 60', "[smoke] 'env.heigth': unknown field; known: difficulty"),
        ('[smoke]\n"ppo.lr" = "fast"', "[smoke] 'ppo.lr': expected a number, got 'fast'"),
        ('[smoke]\n"env.shaping" = 1', "[smoke] 'env.shaping': expected true or false, got 1"),
        ('[smoke]\nseeds = [0, "1"]', "[smoke]: 'seeds' must be a non-empty list of integers"),
        ("[smoke]\nframes_hard = 1.5", "[smoke]: 'frames_hard' must be an integer"),
        ("smoke = 3", "[smoke]: a profile is a table of TrainConfig fields"),
    ],
)
def test_a_broken_profiles_file_is_named_with_the_profile_and_field(tmp_path, monkeypatch, text, message):
    path = tmp_path / "profiles.toml"
    path.write_text(text)
    with pytest.raises(ProfileError) as e:
        load_profiles(path)
    assert str(e.value).startswith(str(path)) and message in str(e.value)
    monkeypatch.setattr(emml.config.profiles, "PROFILES_FILE", path)
    for command in (["list"], ["train", "--profile", "smoke"], ["tasks", "show"]):
        result = CliRunner().invoke(app, command)
        assert result.exit_code == 2 and result.output.startswith(f"error: {path}"), result.output
        assert "Traceback" not in result.output and message in result.output


def test_a_missing_profiles_file_is_named(tmp_path):
    with pytest.raises(ProfileError, match="cannot be read"):
        load_profiles(tmp_path / "nope.toml")


@pytest.mark.parametrize(
    "option, message",
    [
        ('frames="lots"', "--set 'frames': expected an integer, got 'lots'"),
        ("env.shaping=1", "--set 'env.shaping': expected true or false, got 1"),
        ("fraems=5", "--set 'fraems': unknown field"),
        (
            "model_options.state_temprature=0.25",
            "model_options: 'state_temprature' is not an option of model 'dual_attention'; its options: embed_dim",
        ),
        ("model_options.2x=1", "--set 'model_options.2x': not a model option name"),
        ("model_options.state_temperature=-1", "ModelConfig.state_temperature=-1 must be None (off) or a number > 0"),
    ],
)
def test_a_wrong_set_override_is_named_as_such(option, message, tmp_path):
    result = CliRunner().invoke(
        app, ["train", "--profile", "smoke", "--set", option, "--set", f'run_root="{tmp_path}"']
    )
    assert result.exit_code == 2 and message in result.output, result.output
    assert list(tmp_path.iterdir()) == []
    assert str(PROFILES_FILE) not in result.output  # the option is blamed, not the profile


def test_the_house_gets_its_own_env_config_from_a_profile_a_set_and_a_saved_run():
    from emml.config.schema import HouseConfig, TrainConfig, apply_overrides

    profiles = load_profiles()
    cfg = profile_config("quick", "house")  # Appendix C: 50M frames at the paper profile, as in Hard
    assert isinstance(cfg.env, HouseConfig) and cfg.frames == profiles["quick"]["frames_hard"]
    assert cfg.env.max_steps == 420 and cfg.env.dataset == "house" and cfg.env.height == 84
    assert run_name(cfg) == "dual_attention-house-noaux-s0-quick"
    back = TrainConfig.from_dict(cfg.to_dict())
    assert isinstance(back.env, HouseConfig) and back.to_dict() == cfg.to_dict()
    # --set env.difficulty switches the class; fields set away from their defaults survive, the rest are the House's
    cfg = apply_overrides(TrainConfig(), {"env.width": 108, "env.difficulty": "house"})
    assert isinstance(cfg.env, HouseConfig) and cfg.env.width == 108 and cfg.env.max_steps == 420
    cfg = apply_overrides(cfg, {"env.difficulty": "easy"})
    assert type(cfg.env).__name__ == "DoomConfig" and cfg.env.max_steps == TrainConfig().env.max_steps
    with pytest.raises(ValueError, match=r"env.difficulty='attic' is not allowed.*'easy', 'hard', 'house'"):
        apply_overrides(TrainConfig(), {"env.difficulty": "attic"}).validate()


def test_a_model_option_is_set_from_the_command_line_and_recorded():
    from emml.config.schema import TrainConfig, apply_overrides

    cfg = apply_overrides(TrainConfig(), {"model_options.state_temperature": 0.25}).validate()
    assert cfg.model_options == {"state_temperature": 0.25}
    assert TrainConfig.from_dict(cfg.to_dict()).model_options == {"state_temperature": 0.25}  # saved with the run
    assert run_name(cfg) == "dual_attention-easy-noaux-xs0.25-s0-paper"  # beside the default run, not over it
    assert run_name(TrainConfig()) == "dual_attention-easy-noaux-s0-paper"
    mean = apply_overrides(TrainConfig(), {"model_options.sentence_readout": "mean"}).validate()
    assert run_name(mean) == "dual_attention-easy-noaux-sentmean-s0-paper"  # issue 34's opt-in readout, spelled
    soft = apply_overrides(TrainConfig(), {"model_options.sentence_activation": "softplus"}).validate()
    assert run_name(soft) == "dual_attention-easy-noaux-xsentsoftplus-s0-paper"  # and its opt-in activation
    content = apply_overrides(TrainConfig(), {"model_options.eq1_words": "content"}).validate()
    assert run_name(content) == "dual_attention-easy-noaux-eq1content-s0-paper"  # and its opt-in Eq. 1 words
    answer = apply_overrides(TrainConfig(aux=True), {"model_options.answer_grad": "gate"}).validate()
    assert run_name(answer) == "dual_attention-easy-aux-ansgate-s0-paper"  # and its opt-in answer-loss reach
    balanced = apply_overrides(TrainConfig(aux=True), {"ppo.aux_balance": "word"}).validate()
    assert run_name(balanced) == "dual_attention-easy-aux-auxbalword-s0-paper"  # and its opt-in aux balance
    with pytest.raises(ValueError, match="PPOConfig.aux_balance='class' is not allowed; choose one of 'none', 'word'"):
        apply_overrides(TrainConfig(), {"ppo.aux_balance": "class"}).validate()


def test_a_bf16_run_is_named_apart_from_its_fp32_run():
    from emml.config.schema import TrainConfig, apply_overrides

    assert run_name(apply_overrides(TrainConfig(), {"precision": "bf16"})) == "dual_attention-easy-noaux-bf16-s0-paper"


def test_the_callers_fields_win_over_the_profile_and_smoke_writes_under_scratch(tmp_path):
    smoke = profile_config("smoke")
    assert (smoke.run_root, smoke.results_root) == ("scratch/runs", "scratch/results")  # gitignored: not results
    mine = profile_config("smoke", run_root=str(tmp_path), results_root=str(tmp_path / "r"))
    assert (mine.run_root, mine.results_root) == (str(tmp_path), str(tmp_path / "r"))
    assert emml.config.profiles.is_scratch("smoke") and not emml.config.profiles.is_scratch("quick")
