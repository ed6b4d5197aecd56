"""The model registry: the paper's models declared once, in the order and with the switches `emml models` has always
shown, and what each fusion needs read from its declared attributes."""

import pytest

from emml.models import ARCHITECTURES, MODELS, ModelConfig, build_model, check_architecture, model_config
from emml.models.baselines import Pacman
from emml.models.fusion import DualAttention, Fusion
from emml.models.registry import architecture

PAPER = {
    "text_only": {"name": "text_only"},
    "image_only": {"name": "image_only"},
    "concat": {"name": "concat"},
    "ga": {"name": "ga"},
    "film": {"name": "film"},
    "pacman": {"name": "pacman"},
    "dual_attention": {"name": "dual_attention"},
    "da_no_sa": {"name": "dual_attention", "spatial_attention": False},
    "da_no_ga1": {"name": "dual_attention", "ga1": False},
    "da_no_ga2": {"name": "dual_attention", "ga2": False},
    "da_no_indicator": {"name": "dual_attention", "task_indicator": False},
}
"""Every model of the paper with the ModelConfig fields it sets, in the order of `emml models` (before issue 35)."""


def test_the_paper_models_in_their_order_with_their_switches():
    paper = [name for name, spec in MODELS.items() if spec.source == "emml"]
    assert paper == list(PAPER)
    assert {name: MODELS[name].options for name in PAPER} == PAPER
    assert [a for a in ARCHITECTURES if MODELS[a].source == "emml"] == list(PAPER)[:7]
    for name, options in PAPER.items():
        cfg = model_config(name)
        assert {k: getattr(cfg, k) for k in options} == options


def test_every_fusion_is_a_fusion_and_declares_what_it_needs():
    for name in ARCHITECTURES:
        assert issubclass(architecture(name), Fusion)
    assert [a for a in ARCHITECTURES if architecture(a).frame_window] == ["pacman"]
    assert Pacman.frame_window == "pacman_frames" and DualAttention.ablations == ("spatial_attention", "ga1", "ga2")
    assert build_model("pacman", 6, 60, 108, 20, pacman_frames=3).window == 3  # K from the declared field
    assert build_model("film", 6, 60, 108, 20).window == 0
    assert not build_model("image_only", 6, 60, 108, 20).text_encoder.sentence  # uses_sent False: no GRU
    assert build_model("da_no_ga2", 6, 60, 108, 20).text_encoder.sentence is False


def test_unknown_names_point_at_plugins():
    with pytest.raises(ValueError, match="--plugin"):
        model_config("mine")
    with pytest.raises(ValueError, match="EMML_PLUGINS"):
        check_architecture(ModelConfig(name="mine"))
    with pytest.raises(ValueError, match="known names: text_only, image_only"):
        architecture("mine")
