"""Issue 52 (4): a model option is declared once (`model_option`: its default, run-name part and choices), checked
from its declaration, and named from it: the config layer's half, no model registry (no torch) needed."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import pytest

from emml.config.schema import (
    SHARED_MODEL_OPTIONS,
    ModelConfig,
    TrainConfig,
    check_model_options,
    model_option,
)
from emml.runs.naming import named_options, option_name_parts, spelled_name


@dataclass
class Mine:
    scale: float | None = model_option(None, name="sc{}")
    """A number or None; named 'sc0.5'."""
    mode: Literal["a", "b"] = model_option("a", name="mode{}")
    """A Literal: its values are its choices."""
    kind: str = model_option("x", choices=("x", "y"))
    """Declared choices; no name part."""
    on: bool = model_option(False, name="on{}")
    """A bool named by its str."""


def test_the_declared_options_spell_their_parts_in_declaration_order_when_not_default():
    assert named_options(Mine) == ("scale", "mode", "on")
    assert option_name_parts(Mine, {"mode": "b", "scale": 0.5, "kind": "y"}) == ["sc0.5", "modeb"]
    assert option_name_parts(Mine, {"scale": 2, "on": True}) == ["sc2", "onTrue"]  # an int formats as {:g}
    assert option_name_parts(Mine, {"scale": None, "mode": "a", "other": 1}) == []  # the defaults: not spelled
    assert named_options(ModelConfig) == ("sentence_readout", "sentence_activation", "answer_gate_frames")
    spelled = {"answer_gate_frames": 400000, "sentence_activation": "softplus", "sentence_readout": "mean"}
    assert option_name_parts(ModelConfig, spelled) == ["sentmean", "xsentsoftplus", "warm400000"]


@pytest.mark.parametrize(
    "values,message",
    [
        ({"scale": "big"}, "Mine.scale='big' must be a number or None"),
        ({"mode": "c"}, "Mine.mode='c' is not allowed; choose one of 'a', 'b'"),
        ({"kind": "z"}, "Mine.kind='z' is not allowed; choose one of 'x', 'y'"),
        ({"on": 1}, "Mine.on=1 must be true or false"),
    ],
)
def test_a_value_is_checked_against_its_declaration_naming_the_field(values, message):
    with pytest.raises(ValueError) as err:
        check_model_options(Mine, values, "Mine")
    assert str(err.value) == message
    assert check_model_options(Mine, {"scale": 1, "mode": "b"}) == Mine(scale=1, mode="b")


def test_the_configs_leave_a_models_own_options_to_its_declaration():
    assert "ga1" not in SHARED_MODEL_OPTIONS and "hidden" in SHARED_MODEL_OPTIONS and "name" not in SHARED_MODEL_OPTIONS
    cfg = TrainConfig(model_options={"gain": 2}).validate()  # the model's fusion declares it or not: the registry's
    with pytest.raises(ValueError, match=r"spelled_name: model options \['gain'\] need the declared options"):
        spelled_name(cfg, None)
    assert spelled_name(cfg, Mine) == "dual_attention-easy-noaux-s0-paper"  # declared by none: spelled by none
    with pytest.raises(ValueError, match="model_options: 'name' is not a model option name"):
        TrainConfig(model_options={"name": "ga"}).validate()
    with pytest.raises(AttributeError, match="ModelConfig of model 'dual_attention' has no option 'ga1'"):
        ModelConfig().ga1  # noqa: B018 - its fusion's options are filled in by the model registry


def test_each_set_of_choices_has_one_home_that_every_reader_reads():
    """The activations (x_sent's, the baselines' answer head's, the EQA probe's, the command line's) and x_image's
    values are listed once, in emml/config/model.py: a second list (a mutant giving the baselines
    ('relu', 'softplus', 'tanh')) would let one option accept what another refuses."""
    import typing
    from dataclasses import fields

    from emml.cli.common import Activation
    from emml.config.model import ACTIVATIONS, X_IMAGES
    from emml.config.model_options import CHOICES
    from emml.eval.probe_eqa import ProbeOptions
    from emml.models.baselines import BaselineOptions
    from tests.spelled import spelled

    declared = {f.name: f.metadata.get(CHOICES) for f in [*fields(ModelConfig), *fields(BaselineOptions)]}
    assert declared["sentence_activation"] is ACTIVATIONS and declared["answer_activation"] is ACTIVATIONS
    assert declared["x_image"] is X_IMAGES
    probe = typing.get_type_hints(ProbeOptions)["activation"]
    assert typing.get_args(probe) == typing.get_args(Activation) == ACTIVATIONS
    home = "emml/config/model.py:"
    for values in (ACTIVATIONS, X_IMAGES):
        assert [s for s in spelled(values) if not s.startswith(home)] == []
