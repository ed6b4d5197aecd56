"""The env configs (emml/config/env.py): the tasks a run plays."""


def test_the_tasks_a_config_plays_in_the_one_order():
    from emml.config.env import TASKS, DoomConfig, HouseConfig
    from emml.tasks.language import TASKS as LANGUAGE_TASKS

    assert TASKS == ("sgn", "eqa") and LANGUAGE_TASKS is TASKS  # one list: language reads the config's
    assert DoomConfig().played == ("sgn", "eqa") and DoomConfig(tasks="eqa").played == ("eqa",)
    assert HouseConfig(tasks="sgn").played == ("sgn",)
