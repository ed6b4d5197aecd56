"""The diagnostics of emml/eval/diagnose.py measure what they claim: detector AP, attention on the referent, and the
actor's sensitivity to where the referent stands."""

from types import SimpleNamespace

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from emml.config.schema import DoomConfig
from emml.eval.diagnose import (
    average_precision,
    conv3_drift,
    diagnose,
    saturation_warning,
    summary_line,
    x_image_saturation,
)
from emml.models import build_model
from emml.tasks.language import Vocabulary, load_dataset
from tests.conftest import SMOKE
from tests.fakes import ScriptedModel

SGN = ("go to the blue torch", "go to the green armor", "go to the yellow keycard")


def test_average_precision_known_values():
    assert average_precision(np.array([0.9, 0.8, 0.1]), np.array([1, 1, 0])) == 1.0
    assert average_precision(np.array([0.9, 0.8, 0.1]), np.array([0, 0, 1])) == pytest.approx(1 / 3)
    assert average_precision(np.array([0.9, 0.5, 0.1]), np.array([1, 0, 1])) == pytest.approx((1 + 2 / 3) / 2)
    assert np.isnan(average_precision(np.array([0.2, 0.1]), np.array([0, 0])))


@given(st.lists(st.tuples(st.floats(0, 1), st.booleans()), min_size=1, max_size=40))
def test_average_precision_is_in_unit_interval_and_one_for_a_perfect_ranking(pairs):
    scores = np.array([s for s, _ in pairs])
    labels = np.array([y for _, y in pairs])
    ap = average_precision(scores, labels)
    if not labels.any():
        assert np.isnan(ap)
        return
    assert 0.0 < ap <= 1.0
    assert average_precision(labels.astype(float), labels) == 1.0  # positives ranked first


def _env_cfg():
    ds = load_dataset("doom")
    return DoomConfig(**SMOKE, instructions=SGN, vocabulary=Vocabulary.from_dataset(ds).words)


def test_perfect_detectors_attend_to_the_referent(no_leftovers):
    """With x_I := the aux labels, Eq. 2's argmax lies on the referent whenever it is in view (its words are on
    only there: the distractors do not match the instruction)."""
    cfg = _env_cfg()
    model = build_model(
        "dual_attention", len(cfg.vocabulary), cfg.height, cfg.width, cfg.max_steps, control="detectors"
    )
    result = diagnose(model, cfg, episodes=3, step0_episodes=0, max_frames=150)
    assert result["attention_on_target"] == 1.0
    assert result["attention_mass_on_target"] > 0.3
    assert result["actor_sensitivity"] is None and result["frames"] > 0
    words = set(result["detector_ap_words"])
    assert words and not words & {"go", "the", "object"}  # function words: no positives, no AP
    assert "attention_on_target 1.00" in summary_line(result)


class _Scripted(ScriptedModel):
    """Moves by the column of the referent's cells (privileged), or ignores them: two ends of the sensitivity."""

    def __init__(self, vocab_size, reacts: bool):
        super().__init__()
        self.vocab_size, self.reacts = vocab_size, reacts

    def forward(self, obs, state, episode_start):
        t, b = obs["time"].shape
        logits = torch.zeros(t, b, 4)
        if self.reacts:
            column = obs["target"].float().sum(-2).argmax(-1)  # (t, b) in 0..4
            logits[..., 0] = 5.0 * (column == 2)
            logits[..., 1] = 5.0 * (column < 2)
            logits[..., 2] = 5.0 * (column > 2)
        out = SimpleNamespace(logits=logits, aux_logits=torch.zeros(t, b, self.vocab_size, 2, 5), attention=None)
        return out, state


@pytest.mark.parametrize("reacts, low, high", [(True, 0.9, 1.0), (False, 0.0, 0.0)])
def test_actor_sensitivity_separates_a_reacting_actor(reacts, low, high, no_leftovers):
    cfg = _env_cfg()
    result = diagnose(_Scripted(len(cfg.vocabulary), reacts), cfg, episodes=1, step0_episodes=30, max_frames=5)
    assert low <= result["actor_sensitivity"] <= high
    assert result["attention_on_target"] is None
    assert len(result["step0_moves"]) >= 3


def test_saturation_flags_pinned_and_dead_channels():
    """Channel 0 pinned high, 1 pinned low, 2 live: sigmoid counts the first two; ReLU counts only the dead one."""
    z = np.zeros((4, 3, 2, 5))
    z[:, 0], z[:, 1] = 9.0, -9.0
    z[:, 2] = np.random.default_rng(0).normal(0, 2, size=(4, 2, 5))
    sig = x_image_saturation(z, "sigmoid")
    assert sig["x_image_saturated"] == pytest.approx(2 / 3)
    assert [c["pinned"] for c in sig["x_image_channels"].values()] == [True, True, False]
    assert sig["x_image_channels"][0]["spatial_std"] < 1e-3 < sig["x_image_channels"][2]["spatial_std"]
    relu = x_image_saturation(z, "relu")
    assert [c["pinned"] for c in relu["x_image_channels"].values()] == [False, True, False]
    z[0, 0, 0, 0] = 1.0  # one live cell in one frame: no longer pinned
    assert not x_image_saturation(z, "sigmoid")["x_image_channels"][0]["pinned"]
    with pytest.raises(ValueError, match="x_image='tanh'"):
        x_image_saturation(z, "tanh")


def test_a_saturated_conv_is_flagged_on_real_frames(no_leftovers):
    """A Dual-Attention conv3 shifted as the No Aux runs' was (a uniform signed weight shift over the non-negative
    relu(conv2)): every channel pinned, x_I constant, the trainer's warning on; the fresh conv: none pinned."""
    cfg = _env_cfg()
    model = build_model("dual_attention", len(cfg.vocabulary), cfg.height, cfg.width, cfg.max_steps)
    fresh = diagnose(model, cfg, episodes=1, step0_episodes=0, max_frames=20)
    assert fresh["x_image_saturated"] == 0.0 and fresh["x_image_spatial_std"] > 0
    assert saturation_warning(fresh) is None
    with torch.no_grad():
        conv3 = model.image_encoder.conv3
        sign = torch.where(torch.arange(conv3.out_channels) % 2 == 0, 1.0, -1.0).view(-1, 1, 1, 1)
        conv3.weight.add_(sign * 0.05)
        conv3.bias.copy_(sign.view(-1) * 6.0)
    collapsed = diagnose(model, cfg, episodes=1, step0_episodes=0, max_frames=20)
    assert collapsed["x_image_saturated"] == 1.0
    assert collapsed["x_image_spatial_std"] < 1e-3
    assert "pinned" in saturation_warning(collapsed)
    assert "x_image_saturated 1.00" in summary_line(collapsed)


def test_saturation_counts_only_the_channels_asked_for():
    z = np.zeros((4, 3, 2, 5))
    z[:, 0] = -9.0  # pinned, but a channel the caller leaves out
    z[:, 1:] = np.random.default_rng(0).normal(0, 2, size=(4, 2, 2, 5))
    every = x_image_saturation(z, "sigmoid")
    assert every["x_image_saturated"] == pytest.approx(1 / 3)
    some = x_image_saturation(z, "sigmoid", np.array([False, True, True]))
    assert some["x_image_saturated"] == 0.0 and some["x_image_spatial_std"] > every["x_image_spatial_std"]
    assert [c["counted"] for c in some["x_image_channels"].values()] == [False, True, True]
    assert some["x_image_channels"][0]["pinned"]  # still told per channel
    with pytest.raises(ValueError, match="at least one channel"):
        x_image_saturation(z, "sigmoid", np.zeros(3, dtype=bool))


def test_an_aux_runs_all_zero_label_channels_are_not_a_collapse(no_leftovers):
    """Issue 61: in a run with aux labels, the function words' channels ('go', 'the', 'what', ...: labels all zero)
    are trained to 0 by the aux loss. Pinned so, they are not counted (the demo's Aux run warned "50% of the conv3
    channels are pinned": its 9 function words and 2 superlatives of 22); without aux labels every channel counts,
    and the warning names the words it counts and those pinned."""
    from dataclasses import replace

    cfg = _env_cfg()
    words = cfg.vocabulary
    function = ["go", "to", "the", "object", "what", "color", "is", "which", "in"]
    model = build_model("dual_attention", len(words), cfg.height, cfg.width, cfg.max_steps)
    with torch.no_grad():  # the aux loss's work: the function words' channels at 0 on every cell
        for w in [*function, "largest", "smallest"]:
            model.image_encoder.conv3.bias[words.index(w)] = -60.0
    aux = diagnose(model, replace(cfg, aux_labels=True), episodes=1, step0_episodes=0, max_frames=20)
    assert aux["x_image_uncounted"] == function
    assert len(aux["x_image_counted"]) == 13 and "red" in aux["x_image_counted"]  # the superlatives count: no label
    assert aux["x_image_saturated"] == pytest.approx(2 / 13)
    assert saturation_warning(aux) is None
    no_aux = diagnose(model, cfg, episodes=1, step0_episodes=0, max_frames=20)
    assert not cfg.aux_labels and no_aux["x_image_uncounted"] == [] and len(no_aux["x_image_counted"]) == 22
    assert no_aux["x_image_saturated"] == pytest.approx(11 / 22)
    warning = saturation_warning(no_aux)
    assert warning.startswith("WARNING: 11 of the 22 conv3 channels counted (50%) are pinned on every cell")
    assert "go, to, the, object, largest, smallest, what, color, is, which, in" in warning
    assert "counted: all 22 words" in warning
    with torch.no_grad():  # and an Aux run whose content words collapsed too: said, naming what it counts
        model.image_encoder.conv3.bias.fill_(-60.0)
    collapsed = diagnose(model, replace(cfg, aux_labels=True), episodes=1, step0_episodes=0, max_frames=20)
    warning = saturation_warning(collapsed)
    assert warning.startswith("WARNING: 13 of the 13 conv3 channels counted (100%)")
    assert "not the 9 whose aux labels are all zero, which the aux loss trains to 0: go, to, the" in warning


def test_conv3_drift_tells_a_uniform_shift_from_learning():
    """The run's init rebuilt from its seed: untouched, no direction; a uniform signed shift (the No Aux collapse's
    signature), every weight one way; independent noise, about half."""
    from emml.config.schema import TrainConfig

    cfg = TrainConfig(model="dual_attention", seed=3, env=_env_cfg())
    torch.manual_seed(cfg.seed)
    model = build_model("dual_attention", len(cfg.env.vocabulary), cfg.env.height, cfg.env.width, cfg.env.max_steps)
    assert conv3_drift(model, cfg) == {"conv3_one_way": None, "conv3_shift": 0.0}
    weight = model.image_encoder.conv3.weight
    with torch.no_grad():
        weight.add_(0.01)
    shifted = conv3_drift(model, cfg)
    assert shifted["conv3_one_way"] == 1.0 and shifted["conv3_shift"] == pytest.approx(0.01 * weight[0].numel())
    with torch.no_grad():
        weight.sub_(0.01).add_(torch.randn(weight.shape, generator=torch.Generator().manual_seed(0)) * 0.01)
    assert 0.4 < conv3_drift(model, cfg)["conv3_one_way"] < 0.6
