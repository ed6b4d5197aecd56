"""Multimodal fusion units of "Embodied Multimodal Multitask Learning"
(Chaplot et al. 2019, arXiv 1902.01385).

Every fusion maps the image representation x_I = sigmoid(conv3) in
R^{V x h x w} and the text representations x_BoW, x_sent in R^V to a state
representation x_S and answer logits (x_Ans = softmax(answer logits)):

* `DualAttention` -- the proposed unit, Section 3.1, Eq. 1-5, with the
  ablation switches of Section 4 ("Ablation tests").
* `TextOnly`, `ImageOnly`, `Concat`, `GatedAttention`, `FiLM` -- appendix
  "Baseline details"; their answer head is x_Ans = softmax(ReLU(Linear(x_S))).
* `Pacman` -- QA attention of Das et al. 2018 over the last K frames.

The baselines and PACMAN are in emml/models/baselines.py; this module holds the base class and Dual-Attention.

The No Aux warm-up (`ModelConfig.answer_gate_frames`, issue 61: one rule for every model whose answer reads x_I) is
the base class's schedule (`Fusion.at_frames`, `Fusion.warming`); each fusion keeps its answer off x_I while it runs.

Each is a `Fusion`: what it needs (x_BoW, x_sent, a window of K frames) is declared as class attributes, which the
model registry (emml/models/registry.py) and `EmmlModel` read, and so are its own options (`Fusion.options`: a
dataclass of `model_option` fields, e.g. `DualAttentionOptions`, its ablation switches and opt-ins).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from emml.config.schema import ANSWER_GRADS, EQ1_WORDS, model_option


@dataclass
class FusionOutput:
    """What a fusion unit hands to the policy module."""

    state: Tensor
    """x_S, (N, D) flattened state representation."""
    answer_logits: Tensor
    """(N, V) pre-softmax answer scores; x_Ans = softmax(answer_logits)."""
    attention: Tensor | None = None
    """(N, h, w) spatial attention map x_spat (Dual-Attention only), else None."""


@dataclass
class FusionOptions:
    """The options a fusion declares of its own (`Fusion.options`): subclass it as a dataclass, one field per
    option, each declared with `emml.config.schema.model_option` (its default, optionally its run-name part and its
    choices) and a docstring below it; `check` refuses values that do not go together. A run sets them as any other
    model option (`TrainConfig.model_options`, ``--set model_options.NAME=VALUE``); a name the model's fusion does
    not declare, or a value of the wrong type or choice, fails naming the field before any compute
    (`emml.models.model_config`). `ModelConfig` reads them through: ``cfg.NAME``."""

    def check(self) -> None:
        """Raise a ValueError naming the field ('ModelConfig.NAME=…') when the values do not go together, or one is
        out of range; the types and choices are already checked. Nothing to check here."""


class Fusion(nn.Module):
    """A fusion unit: (x_I, x_BoW, x_sent) -> `FusionOutput`. Subclass it for a model of your own
    (docs/own-model.md) and register it (`emml.models.register_model`). What it needs is declared by the class
    attributes below; `EmmlModel` reads them, never the class's identity."""

    uses_bow: bool = False
    """Reads x_BoW (N, V), the bag of words (the text encoder computes it either way)."""
    uses_sent: bool = False
    """Reads x_sent (N, V): the text encoder builds its sentence GRU only then; otherwise the fusion gets None."""
    frame_window: str | None = None
    """The option holding K when the unit reads the last K frames (PACMAN: its 'pacman_frames'): it is then called
    with x_I of (N, K, V, h, w), oldest first, and `EmmlModel` carries the window across steps; None: the current
    frame's x_I (N, V, h, w)."""
    ablations: tuple[str, ...] = ()
    """Those of its options (`options`) that are the ablation switches of §4 (spatial_attention, ga1, ga2): a
    diagnostic asks the fusion whether it has the gate it reads (emml/eval/diagnose_eqa.py)."""
    options: type = FusionOptions
    """Its own options: a dataclass type (`FusionOptions`) whose fields are the options a run may set beside the
    ones every model shares (`ModelConfig`); `from_config` reads their values as ``cfg.options``."""
    answer_warmup: bool = False
    """Its answer reads x_I, and it keeps the answer off x_I while `warming` (the No Aux warm-up,
    `ModelConfig.answer_gate_frames`): its forward computes the answer logits from x_I with the gradient stopped then,
    so that the answer loss (and the policy through x_Ans) trains its text side and head but not the conv. True for
    every fusion of the paper but Text only (whose answer reads no image); a plugin's fusion that declares it must do
    the same (a run of one that does not is refused the option)."""
    answer_gate_frames: int = 0
    """The warm-up's length in frames trained (`ModelConfig.answer_gate_frames`, set by the model registry's
    `build_fusion` or `warm_up`); 0: none."""
    warming: bool = False
    """Within the warm-up: the answer kept off x_I (`at_frames` sets it from the frames trained)."""
    state_dim: int
    """D, the size of x_S (N, D) it hands the policy module (set by ``__init__``)."""

    @classmethod
    def from_config(cls, cfg, vocab_size: int, height: int, width: int) -> Fusion:
        """The unit for a V-word vocabulary and a conv3 grid of (height, width) = (h, w), under `ModelConfig` cfg
        (its own options: ``cfg.options``, an instance of `options`); by default ``cls(vocab_size, height, width)``,
        no option read."""
        return cls(vocab_size, height, width)

    def warm_up(self, frames: int) -> Fusion:
        """Keep the answer off x_I for the run's first ``frames`` frames (`ModelConfig.answer_gate_frames`; 0: never);
        the run starts inside the warm-up until `at_frames` says otherwise. Returns ``self``."""
        if frames and not self.answer_warmup:
            raise ValueError(f"{type(self).__qualname__} has no answer warm-up (answer_warmup=False)")
        self.answer_gate_frames = frames
        self.warming = frames > 0
        return self

    def at_frames(self, frames: int) -> None:
        """The frames the run has trained (the trainer's call before each rollout, `EmmlModel.at_frames`): ends the
        warm-up at `answer_gate_frames`."""
        self.warming = frames < self.answer_gate_frames

    def trace_key(self) -> tuple:
        """Its Python-level switches that change what its forward or backward computes during a run (a schedule over
        the frames trained): a CUDA graph captured under one value is not replayed under another
        (emml/rl/graphs.py). The base class's: the answer's warm-up (`warming`)."""
        return (self.warming,)

    @classmethod
    def state_formula(cls, cfg) -> str:
        """x_S as the code computes it under `cfg`, for `emml models` (it fills '{x_S}' in a registry entry's
        description); '' when the description says it."""
        return ""


def gated_attention(y_image: Tensor, y_text: Tensor) -> Tensor:
    """f_GA(y_I, y_T) = M_{y_T} ⊙ y_I: scale channel i of (N, d, h, w) by y_T[:, i]."""
    return y_image * y_text[:, :, None, None]


def spatial_attention(y_image: Tensor, y_spat: Tensor) -> Tensor:
    """f_SA(y_I, y_S) = M_{y_S} ⊙ y_I: scale every channel at (j, k) by y_S[:, j, k]."""
    return y_image * y_spat[:, None, :, :]


class _CenteredGrad(torch.autograd.Function):
    """Identity on (N, C, h, w); backward removes each frame's and channel's mean over the h×w cells from the
    gradient, so that what passes moves a channel at some cells against others, never the whole channel at once."""

    generate_vmap_rule = True  # the packed trainer vmaps the model over its runs (emml/rl/packed.py)

    @staticmethod
    def forward(x: Tensor) -> Tensor:
        return x.view_as(x)

    @staticmethod
    def setup_context(ctx, inputs, output) -> None:
        pass

    @staticmethod
    def backward(ctx, grad: Tensor) -> Tensor:
        return grad - grad.mean(dim=(2, 3), keepdim=True)


def centered_grad(x: Tensor) -> Tensor:
    """x, unchanged; its gradient centred over the cells of every frame and channel (`_CenteredGrad`)."""
    return _CenteredGrad.apply(x)


@dataclass
class DualAttentionOptions(FusionOptions):
    """Dual-Attention's options (`DualAttention.options`): the ablation switches of §4 and the opt-ins measured in
    docs/fidelity.md. The defaults are the paper's model (`state_scale` aside: the paper is silent on it)."""

    spatial_attention: bool = model_option(True)
    """Use the Spatial-Attention unit (Eq. 2-3); False = 'w/o SA' ablation."""
    ga1: bool = model_option(True)
    """Use the BoW Gated-Attention (Eq. 1); False = 'w/o GA1' ablation."""
    ga2: bool = model_option(True)
    """Use the sentence Gated-Attention (Eq. 4); False = 'w/o GA2' ablation."""
    state_scale: bool = model_option(True)
    """Hand the policy x_S = h·w · vec(x_spat) (mean 1 per cell) instead of vec(x_spat) (entries ~1/(h·w)). Paper
    silent on input scaling; measured in docs/fidelity.md."""
    state_temperature: float | None = model_option(None, name="xs{}")
    """Opt-in: hand the policy x_S = h·w · softmax(scores / state_temperature) with the gradient stopped, a sharper
    copy of x_spat (Eq. 2); x_spat itself, Eq. 3-5 and every loss's gradient into the detectors stay as they are.
    None (the default): x_S = h·w · vec(x_spat). The paper is silent on how the policy reads the map: at temperature
    1 a detector that ranks the target first but scores it 0.6 against 0.2 gives it 1.5x a background cell, too
    faint for the actor; measured in docs/fidelity.md. Run name: 'xs0.25'."""
    eq1_words: str = model_option("all", name="eq1{}", choices=EQ1_WORDS)
    """With GA1: the words whose channels Eq. 1 gates x_I with. 'all', the paper's x_BoW of every word of the text
    (the default); or, opt-in, 'content', the dataset's content words only (objects, colours, sizes, superlatives:
    `Dataset.content_words`), so that the function words ('what', 'which', 'is', 'the', 'color', ...) do not add
    their channels to the attention scores of Eq. 2. x_sent still reads every word. The paper is silent on the
    function words: "a particular feature map is activated if and only if the corresponding word occurs in the
    textual input" (§3.1). Measured in docs/fidelity.md (issue 34): their channels, all-zero in the aux labels, learn
    to fire on the kinds of object that were referents of training questions and pull the attention off a test
    question's referent. Run name: 'eq1content'."""
    answer_grad: str = model_option("all", name="ans{}", choices=ANSWER_GRADS)
    """With GA2: what Eq. 5's answer loss trains. 'all', the conv (through x_I and the map of Eq. 1-3) and the GA2
    gate's encoder x_sent, as end-to-end training does (the default; the paper stops no gradient); or, opt-in,
    'gate', x_sent only: x_SA is read with its gradient stopped in Eq. 4-5, so that the detectors learn from the aux
    labels and the policy, not from the answers (without aux labels, the policy alone); or, opt-in, 'centered', both,
    with the gradient that reaches x_I through Eq. 3 centred over the h×w cells of each frame and channel: it raises
    a detector where Eq. 2's map attends against where it does not, and cannot shift a whole channel (which pins
    sigmoid x_I without aux labels: docs/fidelity.md, issue 48). Values are unchanged. Measured in docs/fidelity.md
    (issue 34): retraining a checkpoint's conv offline on EQA frames, the answer loss beside the aux loss holds the
    keys' detectors at AP 0.11-0.33 where the aux loss alone reaches 0.81-0.86. Run name: 'ansgate', 'anscentered'."""

    def check(self) -> None:
        t = self.state_temperature
        if t is not None and not t > 0:
            raise ValueError(f"ModelConfig.state_temperature={t!r} must be None (off) or a number > 0")
        if t is not None and not self.spatial_attention:
            raise ValueError(
                f"ModelConfig.state_temperature={t!r} sharpens the spatial attention map: only with "
                "spatial_attention=True (got False); allowed without it: None"
            )
        for name, part, what in (
            ("eq1_words", "ga1", "chooses the words of Eq. 1"),
            ("answer_grad", "ga2", "sets the answer loss's reach into the conv"),
        ):
            value = getattr(self, name)
            if value != "all" and not getattr(self, part):
                raise ValueError(
                    f"ModelConfig.{name}={value!r} {what}: only with {part}=True (got False); allowed: 'all'"
                )
        if self.answer_grad == "centered" and not self.spatial_attention:  # it centres the gradient Eq. 3 passes
            raise ValueError(
                "ModelConfig.answer_grad='centered' centres the answer's gradient through Eq. 3: only with "
                "spatial_attention=True (got False); allowed without it: 'all', 'gate'"
            )


class DualAttention(Fusion):
    """The Dual-Attention unit f_DA (Section 3.1, Eq. 1-5); parameter-free.

    Full unit::

        x_GA1  = f_GA(x_I, x_BoW)                     (Eq. 1)
        x_spat = softmax_{HxW}(sum_i x_GA1[i])        (Eq. 2)
        x_SA   = f_SA(x_I, x_spat)                    (Eq. 3)
        x_GA2  = f_GA(x_SA, x_sent)                   (Eq. 4)
        x_Ans  = softmax_V(sum_{j,k} x_GA2[:, j, k])  (Eq. 5)
        x_S    = h*w * vec(x_spat)                    (``state_scale``, the default; the paper: vec(x_spat))

    Its options are `DualAttentionOptions` (`options`). Opt-in, ``eq1_words='content'``: Eq. 1 gates with x_BoW * m,
    m the run's content words (1) and function words (0), set from the run's words by `read_words` or restored with
    a checkpoint. Opt-in, ``answer_grad='gate'``: Eq. 4 reads x_SA with its gradient stopped, so that the answer loss
    trains x_sent only; ``answer_grad='centered'``: Eq. 3 reads x_I with its gradient centred over
    the cells (`centered_grad`), so that the answer loss moves a detector where the map attends against where it
    does not, never a whole channel (issue 48); every value is unchanged under both. The No Aux warm-up
    (`ModelConfig.answer_gate_frames`, `Fusion.warming`) reads x_SA as 'gate' does for its first N frames.

    Ablation switches (Section 4, "Ablation tests"):

    * ``ga1=False`` (w/o GA1): no BoW gating; x_spat = softmax(sum_i x_I[i]).
    * ``ga2=False`` (w/o GA2): no sentence gating; answer logits are
      sum_{j,k} x_SA[:, j, k] (x_sent is not used at all).
    * ``spatial_attention=False`` (w/o SA): no spatial map; x_SA := x_I and the
      state is x_S := vec(x_GA1) (V*h*w values) -- our choice: the paper does
      not say what x_S becomes, and its 0.20 SGN accuracy for this ablation
      suggests the state changed rather than staying a softmax map.
      ``attention`` is None in this case.
    * w/o task indicator is a policy-module switch, not part of this unit.
    """

    ablations = ("spatial_attention", "ga1", "ga2")
    options = DualAttentionOptions
    answer_warmup = True

    def __init__(
        self,
        vocab_size: int,
        height: int,
        width: int,
        ga1: bool = True,
        ga2: bool = True,
        spatial: bool = True,
        state_scale: bool = False,
        state_temperature: float | None = None,
        eq1_words: str = "all",
        answer_grad: str = "all",
        answer_gate_frames: int = 0,
    ) -> None:
        super().__init__()
        self.ga1, self.ga2, self.spatial = ga1, ga2, spatial
        self.answer_grad = answer_grad
        self.warm_up(answer_gate_frames)  # the No Aux warm-up (`Fusion.warming`): Eq. 4 reads x_SA detached
        # eq1_mask (V,): the words Eq. 1 gates with under eq1_words='content' (a buffer, saved with the weights);
        # None: every word, and no buffer, so that the paper's unit saves what it always saved
        self.register_buffer("eq1_mask", torch.ones(vocab_size) if eq1_words == "content" else None)
        self.eq1_ready = False
        """Whether `eq1_mask` holds the run's words (`read_words`, or a checkpoint's state dict), not its ones."""
        self.state_temperature = state_temperature
        self.state_scale = float(height * width) if state_scale and spatial else 1.0
        self.uses_bow = ga1
        self.uses_sent = ga2
        self.state_dim = height * width if spatial else vocab_size * height * width

    @classmethod
    def from_config(cls, cfg, vocab_size: int, height: int, width: int) -> DualAttention:
        o: DualAttentionOptions = cfg.options
        return cls(
            vocab_size,
            height,
            width,
            ga1=o.ga1,
            ga2=o.ga2,
            spatial=o.spatial_attention,
            state_scale=o.state_scale,
            state_temperature=o.state_temperature,
            eq1_words=o.eq1_words,
            answer_grad=o.answer_grad,
        )

    def read_words(self, mask: Tensor) -> None:
        """Set Eq. 1's word mask (V,): 1 for a content word, 0 for a function word (eq1_words='content' only)."""
        if self.eq1_mask is None:
            raise RuntimeError("read_words: this unit gates Eq. 1 with every word (eq1_words='all')")
        with torch.no_grad():
            self.eq1_mask.copy_(mask)
        self.eq1_ready = True

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)
        if self.eq1_mask is not None and prefix + "eq1_mask" in state_dict:  # a checkpoint holds the run's words
            self.eq1_ready = True

    @classmethod
    def state_formula(cls, cfg) -> str:
        """The paper's vec(x_spat) (the text after Eq. 5), times h·w under `state_scale` (the default), a sharper
        gradient-stopped copy of the map under `state_temperature`; vec(x_GA1) without spatial attention."""
        o: DualAttentionOptions = cfg.options
        if not o.spatial_attention:
            return "x_S = vec(x_GA1)"
        read = "vec(x_spat)" if o.state_temperature is None else f"softmax(scores / {o.state_temperature:g})"
        return f"x_S = h·w·{read}" if o.state_scale else f"x_S = {read}"

    def forward(
        self, x_image: Tensor, x_bow: Tensor | None, x_sent: Tensor | None, x_extra: Tensor | None = None
    ) -> FusionOutput:
        """x_I (N, V, h, w), x_BoW (N, V), x_sent (N, V) -> FusionOutput.

        ``x_extra`` (N, k, h, w): detections of k new words appended to x_I by the transfer surgery (§5.4,
        emml/eval/transfer.py), with x_BoW then (N, V + k), word V + j gating channel j. They join the attention
        scores of Eq. 1-2 only, as a separate sum, so that an instruction without the new words gives bit for
        bit the scores it gave before; Eq. 3-5 keep the V channels (the new words answer no question)."""
        n, v, h, w = x_image.shape
        words = x_bow[:, :v] if self.ga1 else None
        if self.eq1_mask is not None:  # opt-in: Eq. 1 over the content words only
            if not self.eq1_ready:
                raise RuntimeError(
                    "eq1_words='content' needs the run's words: EmmlModel.read_words(words, dataset) after building "
                    "the model, or load a checkpoint's state dict"
                )
            words = words * self.eq1_mask
        x_ga1 = gated_attention(x_image, words) if self.ga1 else x_image  # Eq. 1
        if self.spatial:
            scores = x_ga1.sum(dim=1)  # Eq. 2: sum over channels
            if x_extra is not None and self.ga1:  # §5.4: the appended channels, gated by their words (Eq. 1)
                scores = scores + gated_attention(x_extra, x_bow[:, v:]).sum(dim=1)
            scores = scores.reshape(n, h * w)
            x_spat = torch.softmax(scores, dim=1).reshape(n, h, w)  # Eq. 2: softmax over HxW
            # Eq. 3; opt-in, the answer loss's gradient into x_I with its cell-wise mean removed (answer_grad)
            x_sa = spatial_attention(centered_grad(x_image) if self.answer_grad == "centered" else x_image, x_spat)
            # x_S = h·w·vec(x_spat) under state_scale (mean 1 per cell; the paper writes vec(x_spat)); opt-in, the
            # policy reads a sharper copy of Eq. 2's map instead, with no gradient back into the scores
            t = self.state_temperature
            read = x_spat.reshape(n, h * w) if t is None else torch.softmax(scores.detach() / t, dim=1)
            state = read * self.state_scale
        else:
            x_spat = None
            x_sa = x_image  # w/o SA: Eq. 2-3 removed
            state = x_ga1.reshape(n, -1)  # w/o SA: x_S = vec(x_GA1)
        # opt-in 'gate', and the No Aux warm-up (`warming`): the answer loss trains x_sent only, not the conv (w/o GA2:
        # nothing; the map of Eq. 1-3 reads x_I alone, so x_SA's every path to a weight is the conv's)
        if self.answer_grad == "gate" or self.warming:
            x_sa = x_sa.detach()
        x_ga2 = gated_attention(x_sa, x_sent) if self.ga2 else x_sa  # Eq. 4
        answer_logits = x_ga2.sum(dim=(2, 3))  # Eq. 5: sum over H, W (softmax outside)
        return FusionOutput(state=state, answer_logits=answer_logits, attention=x_spat)
