"""The env configs (emml/config/env.py): the tasks a run plays, and the dataset splits, each listed once."""

import inspect

import pytest

from tests.spelled import spelled


def test_the_tasks_a_config_plays_in_the_one_order():
    from emml.config.env import TASKS, DoomConfig, HouseConfig
    from emml.tasks.language import TASKS as LANGUAGE_TASKS

    assert TASKS == ("sgn", "eqa") and LANGUAGE_TASKS is TASKS  # one list: language reads the config's
    assert DoomConfig().played == ("sgn", "eqa") and DoomConfig(tasks="eqa").played == ("eqa",)
    assert HouseConfig(tasks="sgn").played == ("sgn",)


def test_the_splits_are_the_configs_and_every_reader_reads_them():
    from emml.cli.common import SPLITS_OR_BOTH
    from emml.config.env import SPLITS, DoomConfig
    from emml.eval import diagnose_sgn, probe_eqa
    from emml.eval.metrics import METRIC_SPLITS
    from emml.tasks import language

    assert SPLITS == ("train", "test")
    assert language.SPLITS is SPLITS and probe_eqa.SPLITS is SPLITS
    assert inspect.signature(diagnose_sgn.diagnose_sgn).parameters["splits"].default is SPLITS
    assert METRIC_SPLITS[: len(SPLITS)] == SPLITS and SPLITS_OR_BOTH == (*SPLITS, "both")
    with pytest.raises(ValueError, match="split='val' is not allowed; choose one of 'train', 'test'"):
        DoomConfig(split="val").validate()


def test_no_module_spells_the_splits_again():
    """A second list of the splits (a mutant writing ('train', 'test', 'val') in the evaluation) would drift from the
    config's; only emml/config/env.py spells them."""
    assert [s for s in spelled(("train", "test")) if not s.startswith("emml/config/env.py:")] == []
