"""The upper bounds of issue 85 (emml/config/checks.py): each field accepts its bound and refuses just past it, the
error naming the field and the allowed range, before any compute; an empty root folder is refused by name."""

from __future__ import annotations

import pytest

from emml.config.checks import MAX_ENVS, MAX_EPISODES, MAX_EPOCHS, MAX_LR, MAX_THREADS
from emml.config.profiles import profile_config


def _validate(**over):
    return profile_config("smoke", "easy", over).validate()


@pytest.mark.parametrize(
    ("field", "bound", "past", "says"),
    [
        ("ppo.lr", MAX_LR, 1.0000001, "PPOConfig.lr=1.0000001 must be a finite number > 0 and <= 1 (MAX_LR)"),
        ("ppo.lr", MAX_LR, 1e308, "PPOConfig.lr=1e+308 must be a finite number > 0 and <= 1 (MAX_LR)"),
        ("ppo.epochs", MAX_EPOCHS, MAX_EPOCHS + 1, "PPOConfig.epochs=101 must be an integer from 1 to 100"),
        ("threads", MAX_THREADS, MAX_THREADS + 1, "threads=1025 must be an integer from 0 to 1024 (MAX_THREADS)"),
        ("acting_threads", MAX_THREADS, MAX_THREADS + 1, "acting_threads=1025 must be an integer from 0 to 1024"),
        ("num_envs", MAX_ENVS, MAX_ENVS + 1, "num_envs=1025 must be an integer from 1 to 1024 (MAX_ENVS)"),
        ("eval_episodes", MAX_EPISODES, MAX_EPISODES + 1, "eval_episodes=100001 must be an integer from 1 to 100,000"),
        ("final_eval_episodes", MAX_EPISODES, MAX_EPISODES + 1, "final_eval_episodes=100001 must be an integer"),
    ],
)
def test_a_value_past_its_bound_is_refused_naming_the_field_and_range_and_the_bound_itself_accepted(
    field, bound, past, says
):
    extra = {"frames": MAX_ENVS * 32} if field == "num_envs" else {}  # one update of 1,024 actors × 32 steps
    _validate(**{field: bound}, **extra)
    with pytest.raises(ValueError) as refused:
        _validate(**{field: past}, **extra)
    assert says in str(refused.value)


@pytest.mark.parametrize("field", ["run_root", "results_root"])
@pytest.mark.parametrize("value", ["", "   "])
def test_an_empty_root_folder_is_refused_by_name(field, value):
    """Issue 85: `--set run_root=` (an empty string) wrote into the checkout's own adhoc/."""
    with pytest.raises(ValueError) as refused:
        _validate(**{field: value})
    assert f"{field}={value!r} must be a folder path, not empty" in str(refused.value)
    _validate(**{field: "scratch/elsewhere"})  # any other folder stays accepted
