"""The model's config: `ModelConfig`, the options every model shares (declared with `model_option`), and the values
of the model options the command line offers (Dual-Attention's included: the command line imports no torch). Every
field has a docstring with its source."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, ClassVar

from pydantic import Field

from emml.config.checks import Frames, Positive, check
from emml.config.model_options import check_model_options, model_option, option_fields

SENTENCE_READOUTS: tuple[str, ...] = ("last", "mean")
"""Values of `ModelConfig.sentence_readout`: the GRU's last output (the paper's reading) or the mean of its outputs."""
ACTIVATIONS: tuple[str, ...] = ("relu", "softplus")
"""The activations an option may put on a Linear's output: the paper's ReLU, or softplus (as non-negative, but never
0, so that no unit can die). The one list of the values of `ModelConfig.sentence_activation` (x_sent's Linear), of the
baselines' option `answer_activation` (their answer head: `emml.models.baselines.BaselineOptions`, which declares it)
and of `emml probe-eqa --activation`; `emml.models.encoders.activation` gives each its function."""
EQ1_WORDS: tuple[str, ...] = ("all", "content")
"""Values of Dual-Attention's option `eq1_words` (`emml.models.fusion.DualAttentionOptions`, which declares it; here
for the command line, which imports no torch): Eq. 1 gates x_I with every word of the text (the paper's x_BoW), or
with its content words only."""
ANSWER_GRADS: tuple[str, ...] = ("all", "gate", "centered")
"""Values of Dual-Attention's option `answer_grad` (`emml.models.fusion.DualAttentionOptions`): Eq. 5's answer loss
trains the conv and x_sent (the paper's, end to end), x_sent only, or both with its gradient into x_I centred over
the cells."""
X_IMAGES: tuple[str, ...] = ("sigmoid", "relu")
"""Values of `ModelConfig.x_image`: what the fusion reads as x_I from the conv3 logits."""
CONTROLS: tuple[str, ...] = ("none", "detectors", "target_mask", "type_gate")
"""Values of `ModelConfig.control`: the model itself, and the three diagnostic controls."""
LABEL_CONTROLS: tuple[str, ...] = ("detectors", "target_mask")
"""The controls that read the env's privileged aux labels (acting needs them; training needs aux=True)."""


@dataclass
class ModelConfig:
    """A model's configuration: the options every model shares (the encoders, the policy module, the diagnostic
    controls), declared here, and ``options``, those its fusion declares itself (`emml.models.Fusion.options`:
    Dual-Attention's ablations and opt-ins, PACMAN's window, a plugin's own), read through as attributes
    (``cfg.ga1`` is ``cfg.options.ga1``). Built by `emml.models.model_config` from a registry entry and
    `TrainConfig.model_options`."""

    NOT_OPTIONS: ClassVar[tuple[str, ...]] = ("name", "options")
    """The fields that are no option a run sets (not a field): the model's name and its fusion's options
    (`option_fields`)."""

    name: Annotated[str, Field(min_length=1), "the name of a fusion architecture"] = "dual_attention"
    """Fusion architecture, one of `emml.models.ARCHITECTURES`: a fusion class of the model registry,
    emml/models/registry.py (ablations are its options)."""
    embed_dim: Positive = model_option(32)
    """Word-embedding size (paper appendix: 32)."""
    gru_text: Positive = model_option(32)
    """Hidden size of the sentence GRU (paper appendix: 32)."""
    hidden: Positive = model_option(128)
    """Hidden size of the policy's linear layer and GRU (paper appendix: 128)."""
    time_dim: Positive = model_option(32)
    """Size of the learned time-step embedding (paper is silent; our choice)."""
    task_indicator: bool = model_option(True)
    """Feed the SGN/EQA task one-hot to the policy; False = 'w/o task indicator' ablation."""
    sentence_readout: str = model_option("last", name="sent{}", choices=SENTENCE_READOUTS)
    """Which GRU output x_sent's Linear reads (§3: x_sent = f(T; θ_sent), "passing the words in T through a GRU
    network followed by a linear layer"): 'last', the GRU's output after the last word (the paper's reading, the
    default); or, opt-in, 'mean', the mean of its outputs over the words, which keeps the question word ('what' /
    'which') in x_sent. Measured in docs/fidelity.md (issue 34): with 'last', a test question ending in a word no
    training question ends in gets the GA2 gate of the instructions ending in it ('what color is the torch'
    answered 'torch')."""
    sentence_activation: str = model_option("relu", name="xsent{}", choices=ACTIVATIONS)
    """The activation on x_sent's Linear (§3: "the linear layer with ReLU activations"; "ReLU activations for
    sentence embedding ensure aggregation"): 'relu', the paper's, the default; or, opt-in, 'softplus', as
    non-negative but never 0, so that no gate channel can die. Measured in docs/fidelity.md (issue 34): under ReLU a
    channel whose pre-activation is negative for every question gets no gradient from the answer loss and its word
    can never be answered (seed 0: 'blue' with the last readout; 'torch', 'skullkey' and 'blue' with the mean)."""
    answer_gate_frames: Frames = model_option(0, name="warm{}")
    """The No Aux warm-up (issue 48, made one rule for every model by issue 61): for the run's first N frames the
    answer's gradient is kept off the image encoder (the conv) and every path from it, then the answer loss trains
    end to end as the paper has it; 0: off (the paper's loss from the start). Values are unchanged. Where the fusion
    has a GA2 gate (Dual-Attention), the answer loss keeps to that gate and x_sent; where it has none (the baselines,
    Dual-Attention w/o GA2), to its text side and answer head. Every fusion of the paper whose answer reads x_I takes
    it (`emml.models.Fusion.answer_warmup`); Text only's answer reads no image, and refuses it. Why: without aux
    labels, end to end from the start, the answer loss pins whole conv3 channels within ~100k frames (Dual-Attention,
    GA, FiLM: docs/fidelity.md, "No Aux"). The trainer sets it from the frames trained (`EmmlModel.at_frames`), so a
    resumed run resumes the schedule. Run name: 'warm<N>'."""
    x_image: str = model_option("sigmoid", choices=X_IMAGES)
    """What the fusion reads as x_I from the conv3 logits z: 'sigmoid' (Appendix A: sigmoid on conv3) or 'relu'
    (§3.1 after Eq. 2: 'ReLU activations in the convolutional feature maps'); the aux task predicts sigmoid(z)
    either way. The paper contradicts itself; measured in docs/fidelity.md."""
    control: str = model_option("none", choices=CONTROLS)
    """Diagnostic controls, not the paper's model (they read privileged labels, so they need aux labels):
    'none'; 'detectors': x_I := the aux labels (perfect detectors, unlabelled channels 0); 'target_mask':
    x_S := the cells showing the episode's referent (perfect x_S, values 0/1); 'type_gate' (Dual-Attention with GA2,
    evaluation only: `emml eval CKPT --control type_gate`): Eq. 4's x_sent := a gate from the dataset's word types
    that opens the channels of the attribute a question asks for (emml/models/type_gate.py), no labels read."""
    options: object = None
    """The fusion's own options, an instance of its `Fusion.options` class (Dual-Attention's:
    `emml.models.fusion.DualAttentionOptions`); None until the model registry fills in its defaults
    (`emml.models.registry.check_architecture`)."""

    def __getattr__(self, name: str):
        """A fusion option read through: ``cfg.ga1`` is ``cfg.options.ga1``."""
        options = self.__dict__.get("options")
        if not name.startswith("__") and options is not None and hasattr(options, name):
            return getattr(options, name)
        raise AttributeError(f"{type(self).__name__} of model {self.__dict__.get('name')!r} has no option {name!r}")

    def validate(self) -> ModelConfig:
        """The shared options' values: raise `ValueError` naming the offending field; return self when valid. The
        fusion's own options, and whether `name` is registered, are the model registry's check
        (`emml.models.registry.check_architecture`), made where a model is built or a run starts."""
        check(self, "ModelConfig.", ("name",))
        check_model_options(ModelConfig, {name: getattr(self, name) for name in option_fields(ModelConfig)})
        return self


SHARED_MODEL_OPTIONS: tuple[str, ...] = tuple(option_fields(ModelConfig))
"""The names `TrainConfig.model_options` may set for every model: the options `ModelConfig` declares. A model's
fusion declares more (`emml.models.Fusion.options`), checked where the model registry is read
(`emml.models.model_config`: where a run starts, a table is read, a model is built)."""
