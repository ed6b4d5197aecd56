"""emml/experiments/fidelity.py: the declared settings of the paper, compared with a config."""

import pytest

from emml.config.profiles import profile_config
from emml.experiments import fidelity


def test_every_declared_field_is_a_field_of_the_resolved_config():
    """A setting's fields are in the resolved config of every paper model it applies to (a fusion's own options,
    e.g. PACMAN's window, only in its models'), and every setting applies to one of them."""
    from emml.models import MODELS

    applied = set()
    for model in [m for m, spec in MODELS.items() if spec.source == "emml"]:
        cfg = fidelity.resolve(
            profile_config("paper", model=model, aux=True, overrides={"precision": "bf16"}).to_dict()
        )
        for entry in (*fidelity.PAPER, *fidelity.CHOICES):
            if entry.applies(cfg):
                assert set(entry.fields) <= set(cfg), (model, entry.label)
                applied.add(entry.label)
    assert applied == {entry.label for entry in (*fidelity.PAPER, *fidelity.CHOICES)}


@pytest.mark.parametrize("difficulty", ["easy", "hard", "house"])
def test_the_paper_profile_deviates_only_where_we_chose_to(difficulty):
    cfg = fidelity.resolve(profile_config("paper", difficulty, model="dual_attention", aux=True).to_dict())
    assert fidelity.deviations(cfg) == ["x_S = h·w·vec(x_spat) (paper vec(x_spat), text after Eq. 5)"]
    unscaled = profile_config("paper", difficulty, {"model_options.state_scale": False}, model="dual_attention")
    assert fidelity.deviations(fidelity.resolve(unscaled.to_dict())) == []
    assert fidelity.deviations(fidelity.resolve(profile_config("paper", difficulty, model="ga").to_dict())) == []


def test_the_quick_profile_names_its_input_frames_and_sources():
    easy = fidelity.deviations(fidelity.resolve(profile_config("quick", "easy", model="ga").to_dict()))
    assert easy == ["input 84×150 (paper 168×300, App. A)", "frames 1.5M (paper 10M, §5.1)"]
    house = fidelity.deviations(fidelity.resolve(profile_config("quick", "house", model="ga").to_dict()))
    assert "frames 5M (paper 50M, App. C)" in house


def test_a_changed_field_is_a_deviation_unless_the_row_sets_it():
    saved = profile_config("paper", model="ga").to_dict()
    saved["env"]["shaping"] = False
    saved["ppo"]["lr"] = 1e-4
    cfg = fidelity.resolve(saved)
    assert fidelity.deviations(cfg) == [
        "reward shaping off (paper on, §5.1)",
        "learning rate 0.0001 (paper 0.00025, App. A)",
    ]
    assert fidelity.deviations(cfg, frozenset({"env.shaping"})) == ["learning rate 0.0001 (paper 0.00025, App. A)"]


@pytest.mark.parametrize(
    "options, absent, named",
    [
        (
            {"sentence_readout": "mean"},
            "x_sent",
            "x_sent read from the mean of the GRU's outputs (paper the GRU's last output, §3: 'a GRU followed by a "
            "linear layer', its final state)",
        ),
        (
            {"sentence_activation": "softplus"},
            "x_sent activation",
            "x_sent activation softplus (never 0) (paper ReLU, §3: 'the linear layer with ReLU activations')",
        ),
        (
            {"eq1_words": "content"},
            "Eq. 1",
            "Eq. 1 gates with the content words only (function words out) (paper every word, §3.1: x_BoW of every "
            "word of the text)",
        ),
        (
            {"answer_grad": "gate"},
            "answer loss",
            "answer loss trains x_sent only (x_SA's gradient stopped in Eq. 4) (paper the conv and x_sent, §3: Eq. "
            "1-5 trained end to end)",
        ),
        (
            {"answer_gate_frames": 400000},
            "answer kept off",
            "answer kept off the image encoder for the first 400,000 frames, then end to end (paper never, §3 and "
            "App. 'Baseline details': every model trained end to end)",
        ),
    ],
)
def test_an_opt_in_model_option_is_named_where_a_run_uses_it(options, absent, named):
    saved = profile_config("quick", "easy", model="dual_attention", aux=True).to_dict()
    assert not any(absent in d for d in fidelity.deviations(fidelity.resolve(saved)))
    saved["model_options"] = options
    assert named in fidelity.deviations(fidelity.resolve(saved))


def test_the_baselines_answer_head_is_named_where_a_baseline_run_uses_softplus():
    def named(model, **options):
        saved = profile_config("quick", "easy", model=model, aux=True).to_dict()
        saved["model_options"] = options
        return [d for d in fidelity.deviations(fidelity.resolve(saved)) if d.startswith("baseline answer head")]

    assert named("concat") == [] and named("dual_attention") == [] and named("pacman") == []
    assert named("text_only", answer_activation="softplus") == [
        "baseline answer head softmax(softplus(Linear(x_S))) (never 0) (paper softmax(ReLU(Linear(x_S))), App. "
        "'Baseline details': 'a linear layer f with ReLU activations followed by softmax')"
    ]


def test_our_choices_follow_the_config():
    saved = profile_config("paper", model="dual_attention", aux=True).to_dict()
    choices = fidelity.choices(fidelity.resolve(saved))
    assert "wrong-object/answer reward 0 (paper silent: §5.1 names only +1 and -0.001 per step)" in choices
    assert any(c.startswith("aux labels for 20 of 22 words: all but the superlatives") for c in choices)
    saved["env"].update(wrong_reward=-0.2, label_grid="even", aux_words=["red", "pillar"])
    choices = fidelity.choices(fidelity.resolve(saved))
    assert "wrong-object/answer reward -0.2 (paper silent: §5.1 names only +1 and -0.001 per step)" in choices
    assert "aux label cells: an even partition of the frame (paper silent)" in choices
    assert any(c.startswith("aux labels for 2 of 22 words: red, pillar") for c in choices)
    no_aux = fidelity.choices(fidelity.resolve(profile_config("paper", model="dual_attention").to_dict()))
    assert not any(c.startswith("aux label") for c in no_aux)


def test_a_config_saved_before_a_field_existed_reads_it_as_the_run_did():
    saved = profile_config("quick", model="dual_attention").to_dict()
    for key in ("precision", "compile", "envs_per_worker", "final_eval_episodes"):
        saved.pop(key, None)
    cfg = fidelity.resolve(saved)
    assert cfg["precision"] == "fp32" and cfg["score_episodes"] == saved["eval_episodes"]


def test_the_balanced_aux_loss_is_named_where_an_aux_run_uses_it():
    saved = profile_config("quick", "easy", model="dual_attention", aux=True).to_dict()
    assert not any(d.startswith("aux loss") for d in fidelity.deviations(fidelity.resolve(saved)))
    saved["ppo"]["aux_balance"] = "word"
    assert (
        "aux loss cross-entropy balanced per word (paper cross-entropy over every cell, 'Auxiliary Task': 'trained "
        "with cross-entropy loss')" in fidelity.deviations(fidelity.resolve(saved))
    )
    saved["aux"] = False  # no aux loss to balance
    assert not any(d.startswith("aux loss") for d in fidelity.deviations(fidelity.resolve(saved)))
