"""Dataclass configs. Every field has a docstring with its unit and source (paper section, or 'our choice' with
the reason, collected in docs/fidelity.md). `validate()` fails before any compute with the field's name and the
allowed values.

Configs are leaves: this module imports no other layer of `emml` but the leaves `emml.config.geometry` and
`emml.config.env_kinds`. What needs more than the values is checked where training starts, not here
(`emml.rl.hardware.check_runnable`): the model registry (plugins loaded) names the model and checks the options
its fusion declares (`model_option`, `emml.models.Fusion.options`); the machine runs `compile` (a C++ compiler),
`precision` (native bf16) and `device` (CUDA)."""

from __future__ import annotations

import math
import re
from dataclasses import Field, asdict, dataclass, field, fields
from typing import ClassVar

from emml.config.env_kinds import DOOM_ID, ENV_KINDS, HOUSE_ID, kinds_of

PLAIN_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
"""A table or profile name: it becomes a folder or file name, so no path separator, no leading dot."""

RESOLUTIONS_16_9 = ((256, 144), (320, 180), (400, 225), (512, 288), (640, 360), (800, 450), (1024, 576))
"""ViZDoom's 16:9 screen resolutions (width, height), the aspect of the paper's 300×168 input."""

VOCABULARY_SOURCES = ("all", "train_instructions")
"""Names a run's `DoomConfig.vocabulary` may give instead of a word list (`Vocabulary.from_dataset`, emml/tasks)."""

COMPILE = ("off", "on", "auto")
"""Values of TrainConfig.compile (emml/rl/compiled.py)."""

PRECISIONS = ("fp32", "bf16")
"""Values of TrainConfig.precision (emml/rl/precision.py)."""


def check_choice(field: str, value, allowed) -> None:
    """Raise a ValueError naming the field and its allowed values."""
    if value not in allowed:
        raise ValueError(f"{field}={value!r} is not allowed; choose one of {', '.join(map(repr, allowed))}")


DEVICES: tuple[str, ...] = ("cpu", "cuda")
"""Kinds of `TrainConfig.device` ('cuda' may name a GPU: 'cuda:1')."""


def check_device_name(device: str) -> None:
    """Raise a ValueError naming the field 'device' and its allowed kinds (whether the machine has it is
    `emml.rl.hardware.check_device`)."""
    check_choice("device", device.split(":")[0], DEVICES)


MAX_FRAMES = 10**10
"""The most frames any frame count may be (frames, eval_every, the No Aux warm-up): 200x the paper's longest
training (50M frames, Doom Hard) and about a month at the fastest rate measured here (4,314 frames/s, 8 stacked runs
on an H100, docs/throughput.md). A larger count is a typo (an extra zero, 1e20), and beyond 2^63 a step no longer
fits MLflow's metric steps (issue 65: 10^20 was accepted and its run named 'warm1e+20')."""


def check_frames(name: str, value) -> None:
    """Raise a ValueError naming ``name`` unless ``value`` is a whole number of frames from 0 to MAX_FRAMES."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_FRAMES:
        raise ValueError(f"{name}={value!r} must be a whole number of frames from 0 to {MAX_FRAMES:,} (MAX_FRAMES)")


def check_at_least(config, names: tuple[str, ...], minimum: int) -> None:
    """Raise a ValueError naming the first of ``config``'s integer fields ``names`` below ``minimum`` (1: a positive
    integer, 0: >= 0)."""
    for name in names:
        value = getattr(config, name)
        if value < minimum:
            raise ValueError(f"{name}={value!r} must be " + ("a positive integer" if minimum == 1 else f">= {minimum}"))


@dataclass
class DoomConfig:
    """The Doom environment `emml/Doom-v0` (paper §4 'Environments', §5.1, Appendix B)."""

    difficulty: str = "easy"
    """'easy': agent fixed, objects at 5 fixed slots in view; 'hard': random agent pose and object positions."""
    split: str = "train"
    """'train' or 'test' instructions/questions (Table 7)."""
    tasks: str = "both"
    """'both' (SGN and EQA, 50/50 per episode), 'sgn' or 'eqa' (single-task ablation, Table 3)."""
    height: int = 168
    """Observation height in pixels (Appendix A: 3×168×300)."""
    width: int = 300
    """Observation width in pixels (Appendix A)."""
    aux_labels: bool = False
    """Add the V×h×w auxiliary detection labels ('aux') to the observation (§3.2 'Auxiliary Task'); with them
    ``info['target_mask']`` gives the h×w cells showing the episode's referent (privileged: no model reads it)."""
    target_in_obs: bool = False
    """With `aux_labels`, put the referent's cells in the observation too ('target'): for the 'target_mask'
    diagnostic control, the one model that reads them (the trainer and the evaluations turn it on for it)."""
    max_steps: int = 210
    """Episode limit in agent steps (§5.1: 'maximum length of 210 time steps')."""
    frame_skip: int = 5
    """Engine tics per agent step (paper silent; the reference SGN environment repeats each action 5 tics)."""
    turn_degrees: float = 15.0
    """Turn per left/right step, in degrees (paper silent; our choice: 3°/tic × 5 tics, 24 steps a full turn)."""
    reach_distance: float = 40.0
    """An object is reached within this 2-D distance of its centre, map units (reference SGN environment)."""
    success_reward: float = 1.0
    """Reaching the right object (SGN) or answering correctly (EQA) (§5.1)."""
    step_reward: float = -0.001
    """Every step (§5.1)."""
    wrong_reward: float = 0.0
    """Reaching a wrong object or answering wrongly. §5.1 names only +1 and -0.001 per step, so 0; the SGN
    environment the paper adapts used -0.2, under which a PPO agent can settle on never touching an object
    (measured in docs/fidelity.md)."""
    shaping: bool = True
    """Distance-based reward shaping in SGN (§5.1; off for the 'w/o reward shaping' ablation, Table 3)."""
    shaping_coef: float = 0.001
    """Shaping reward per map unit of decrease in distance to the target (paper silent: 'small'; ~0.1 per Easy
    episode)."""
    render: str = "auto"
    """ViZDoom render resolution 'WxH' (16:9); 'auto' takes the smallest one at least the observation size."""
    interpolation: str = "linear"
    """Resize filter from render to observation size: 'linear' (our choice: 5× faster than 'area', the reference
    env's cv2.INTER_AREA, and alike at the 0.94 scale of 320×180 → 300×168), 'area' or 'nearest'."""
    label_grid: str = "receptive_field"
    """How label pixels meet the conv3 grid (paper silent): 'receptive_field', the cell whose receptive field is
    centred nearest (emml/config/geometry.py), or 'even', an even partition of the frame (off by up to one cell at
    the right and bottom edges, since conv3 has no padding)."""
    max_words: int = 10
    """Token sequence length (padded with 0)."""
    vocabulary: tuple[str, ...] | str | None = None
    """The run's vocabulary (channel order); None builds the default, every word of the dataset; a name builds
    one from the dataset: 'all' (the default) or 'train_instructions' (the training instructions' words only:
    the transfer experiment, Table 4). The trainer pins it to the word list, saved with the run."""
    aux_words: tuple[str, ...] | None = None
    """Words that get aux labels; None: every word but the superlatives (§3.2; function words get all-zero
    labels). The transfer experiment passes the training words only."""
    instructions: tuple[str, ...] | None = None
    """Restrict episodes to these sentences (must be in the chosen split); None: all of the split."""
    dataset: str = "doom"
    """Which tasks/<name>.toml."""

    GYM_ID: ClassVar[str] = DOOM_ID
    """The environment this class configures (not a field); it plays the kinds of env_kinds.py with this id."""
    DIFFICULTIES: ClassVar[tuple[str, ...]] = kinds_of(DOOM_ID)
    """The allowed `difficulty` values (not a field): Easy and Hard (§4)."""

    def validate(self) -> DoomConfig:
        check_choice("difficulty", self.difficulty, self.DIFFICULTIES)
        check_choice("split", self.split, ("train", "test"))
        check_choice("tasks", self.tasks, ("both", "sgn", "eqa"))
        check_choice("interpolation", self.interpolation, ("area", "linear", "nearest"))
        check_choice("label_grid", self.label_grid, ("receptive_field", "even"))
        if isinstance(self.vocabulary, str):
            check_choice("vocabulary", self.vocabulary, VOCABULARY_SOURCES)
        elif self.vocabulary is not None and not all(isinstance(w, str) for w in self.vocabulary):
            raise ValueError(
                f"vocabulary={self.vocabulary!r} must be a list of words, or one of "
                + ", ".join(map(repr, VOCABULARY_SOURCES))
            )
        from emml.config.geometry import conv_output_size

        conv_output_size(self.height, self.width)  # raises naming height/width when too small
        check_at_least(self, ("max_steps", "frame_skip", "max_words"), 1)
        if self.target_in_obs and not self.aux_labels:
            raise ValueError("target_in_obs=True needs aux_labels=True: the referent's cells come from the labels")
        if self.render != "auto":
            allowed = [f"{w}x{h}" for w, h in RESOLUTIONS_16_9]
            check_choice("render", self.render, ["auto", *allowed])
        if self.render_size()[0] < self.width or self.render_size()[1] < self.height:
            raise ValueError(f"render={self.render!r} is smaller than the observation {self.width}x{self.height}")
        return self

    def render_size(self) -> tuple[int, int]:
        """(width, height) the engine renders at."""
        if self.render == "auto":
            for w, h in RESOLUTIONS_16_9:
                if w >= self.width and h >= self.height:
                    return w, h
            return RESOLUTIONS_16_9[-1]
        w, h = self.render.split("x")
        return int(w), int(h)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class HouseConfig(DoomConfig):
    """The House environment `emml/House-v0` (Appendix C, Table 8): one fixed house of four rooms, the agent's spawn
    fixed, furniture at fixed slots in colours drawn per episode (emml/envs/house.py). Fields not redefined here
    mean what they mean in DoomConfig; the choices where the paper is silent are in docs/fidelity.md."""

    difficulty: str = "house"
    """Always 'house' (one fixed house, Appendix C); kept so run names and code written for DoomConfig read it."""
    max_steps: int = 420
    """Episode limit in agent steps (Appendix C: 'All episodes have a maximum length of 420 time steps')."""
    reach_distance: float = 8.0
    """An object is reached when the player's collision box comes within this many map units of the object's
    (paper silent; furniture differs in size, so not a centre distance as in the Doom room)."""
    shaping_coef: float = 0.00025
    """Shaping reward per map unit of decrease in the path distance (through the doorways) to the referent, in
    SGN and in EQA (Appendix C; paper silent on the scale: ~0.3 over the longest path, spawn to bed, 1,231 units).
    `shaping` turns it off."""
    dataset: str = "house"
    """Table 8 (emml/tasks/house.toml)."""

    GYM_ID: ClassVar[str] = HOUSE_ID
    DIFFICULTIES: ClassVar[tuple[str, ...]] = kinds_of(HOUSE_ID)


ENV_CONFIGS: dict[str, type[DoomConfig]] = {c.GYM_ID: c for c in (DoomConfig, HouseConfig)}
"""The config class of each environment, by gym id."""
ENV_DIFFICULTIES = tuple(ENV_KINDS)
"""Where a run trains: Doom Easy, Doom Hard (§4), or the House (Appendix C): the kinds of emml/config/env_kinds.py."""


def env_config_class(difficulty: str) -> type[DoomConfig]:
    """The environment config a difficulty needs: the class of its kind's gym id (HouseConfig for 'house',
    Appendix C); DoomConfig for a value that is no kind, so that `validate` names it."""
    kind = ENV_KINDS.get(difficulty)
    return ENV_CONFIGS[kind.gym_id] if kind is not None else DoomConfig


def match_env_class(env: DoomConfig) -> DoomConfig:
    """``env`` in the config class its difficulty needs (a run switched to 'house' by a profile or --set gets a
    HouseConfig); fields left at the old class's defaults take the new class's (the House's 420 steps, Table 8)."""
    cls = env_config_class(env.difficulty)
    if type(env) is cls:
        return env
    old, new = type(env)(), cls()
    values = {}
    for f in fields(cls):
        value = getattr(env, f.name)
        values[f.name] = getattr(new, f.name) if value == getattr(old, f.name) else value
    values["difficulty"] = env.difficulty
    return cls(**values)


def config_from_dict(cls, values: dict):
    """Build a config dataclass from a dict, rejecting unknown keys by name (tuples restored from lists)."""
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown {cls.__name__} field(s) {unknown}; known fields: {sorted(known)}")
    fixed = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    return cls(**fixed)


AUX_BALANCES: tuple[str, ...] = ("none", "word")
"""Values of `PPOConfig.aux_balance`: the aux cross-entropy averaged over every cell (the paper's), or balanced per
word between the cells labelled 1 and those labelled 0."""


@dataclass
class PPOConfig:
    """Hyper-parameters of the PPO update (paper appendix A unless noted)."""

    clip_coef: float = 0.2
    """Surrogate clipping epsilon (PPO Eq. 7). Paper: 0.2."""
    gamma: float = 0.99
    """Discount factor. Paper: 0.99."""
    gae_lambda: float = 0.95
    """GAE lambda (Schulman et al. 2016). Paper silent -- our choice (PPO paper's Atari value)."""
    epochs: int = 4
    """Optimisation epochs per rollout. Paper: 4."""
    minibatches: int = 1
    """Minibatches per epoch, split along the env axis so recurrent sequences stay whole. Paper: 1 ("single batch")."""
    lr: float = 2.5e-4
    """Adam learning rate. Paper: 2.5e-4 (constant; no annealing mentioned)."""
    ent_coef: float = 0.01
    """Entropy-bonus coefficient on the move distribution. Paper silent -- our choice (PPO paper's Atari value)."""
    vf_coef: float = 0.5
    """Value-loss coefficient (value loss is 0.5 * MSE). Paper silent -- our choice (CleanRL default)."""
    max_grad_norm: float = 0.5
    """Global gradient-norm clip. Paper silent -- our choice (CleanRL default)."""
    norm_adv: bool = True
    """Normalise advantages per minibatch to zero mean / unit std. Paper silent -- our choice (CleanRL default)."""
    clip_vloss: bool = False
    """Use PPO2-style clipped value loss. Paper silent -- our choice (off; Andrychowicz et al. 2021: no benefit)."""
    answer_coef: float = 1.0
    """Weight of the supervised answer cross-entropy. Paper silent on the weight -- our choice."""
    aux_coef: float = 1.0
    """Weight of the spatial auxiliary binary cross-entropy. Paper silent on the weight -- our choice."""
    aux_balance: str = "none"
    """How the aux cross-entropy weighs a word's cells (`AUX_BALANCES`): "none", the mean over every cell (the paper:
    'trained with cross-entropy loss', 'Auxiliary Task'), or "word" (opt-in), per word the mean over the cells
    labelled 1 and the mean over those labelled 0, halved: a small object's few cells weigh as much as the rest of
    the frame. Retraining a checkpoint's conv on the aux labels alone, it learned the keys no better than the plain
    mean (docs/fidelity.md, "The aux loss's weighting is not what holds them back")."""
    adam_eps: float = 1e-5
    """Adam epsilon. Paper silent -- our choice (CleanRL/baselines PPO value)."""

    def validate(self) -> PPOConfig:
        """Raise ValueError naming the first out-of-range field; return self."""
        positive = ("clip_coef", "lr", "max_grad_norm", "adam_eps")
        non_negative = ("ent_coef", "vf_coef", "answer_coef", "aux_coef")
        unit = ("gamma", "gae_lambda")
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "aux_balance":
                check_choice("PPOConfig.aux_balance", v, AUX_BALANCES)
                continue
            if f.name in ("norm_adv", "clip_vloss"):
                if not isinstance(v, bool):
                    raise ValueError(f"PPOConfig.{f.name} must be a bool, got {v!r}")
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"PPOConfig.{f.name} must be a finite number, got {v!r}")
            if f.name in ("epochs", "minibatches"):
                if not isinstance(v, int) or v < 1:
                    raise ValueError(f"PPOConfig.{f.name} must be an integer >= 1, got {v!r}")
            elif f.name in positive and not v > 0:
                raise ValueError(f"PPOConfig.{f.name} must be > 0, got {v!r}")
            elif f.name in non_negative and not v >= 0:
                raise ValueError(f"PPOConfig.{f.name} must be >= 0, got {v!r}")
            elif f.name in unit and not 0.0 <= v <= 1.0:
                raise ValueError(f"PPOConfig.{f.name} must be in [0, 1], got {v!r}")
        if not self.clip_coef < 1.0:
            raise ValueError(f"PPOConfig.clip_coef must be in (0, 1), got {self.clip_coef!r}")
        return self


SENTENCE_READOUTS: tuple[str, ...] = ("last", "mean")
"""Values of `ModelConfig.sentence_readout`: the GRU's last output (the paper's reading) or the mean of its outputs."""
SENTENCE_ACTIVATIONS: tuple[str, ...] = ("relu", "softplus")
"""Values of `ModelConfig.sentence_activation`: the paper's ReLU on x_sent's Linear, or softplus (never 0)."""
EQ1_WORDS: tuple[str, ...] = ("all", "content")
"""Values of Dual-Attention's option `eq1_words` (`emml.models.fusion.DualAttentionOptions`, which declares it; here
for the command line, which imports no torch): Eq. 1 gates x_I with every word of the text (the paper's x_BoW), or
with its content words only."""
ANSWER_GRADS: tuple[str, ...] = ("all", "gate", "centered")
"""Values of Dual-Attention's option `answer_grad` (`emml.models.fusion.DualAttentionOptions`): Eq. 5's answer loss
trains the conv and x_sent (the paper's, end to end), x_sent only, or both with its gradient into x_I centred over
the cells."""
CONTROLS: tuple[str, ...] = ("none", "detectors", "target_mask", "type_gate")
"""Values of `ModelConfig.control`: the model itself, and the three diagnostic controls."""
LABEL_CONTROLS: tuple[str, ...] = ("detectors", "target_mask")
"""The controls that read the env's privileged aux labels (acting needs them; training needs aux=True)."""

NAME_PART = "name_part"
"""Key of a model option's field metadata (`model_option`): the format of its part of the run name."""
CHOICES = "choices"
"""Key of a model option's field metadata (`model_option`): its allowed values."""


def model_option(default, *, name: str | None = None, choices: tuple | None = None):
    """Declare a model option: a dataclass field of `ModelConfig` (the options every model shares) or of a fusion's
    own options class (`emml.models.Fusion.options`), its docstring below it as for every config field.

    ``default``: its value unless `TrainConfig.model_options` sets it (the paper's, for the paper's models).
    ``name``: the format of its part of the run name, spelled when a run sets it to another value than the default
    ('ans{}' with 'gate' gives 'ansgate'; a number formats as {:g}: 'xs{}' with 0.25 gives 'xs0.25'); None: a run that
    sets it is named by `emml.runs.naming.swept` ('+model_options.NAME=VALUE'), like any other field.
    ``choices``: its allowed values (checked by `check_model_options`, naming the field)."""
    metadata = {}
    if name is not None:
        if not isinstance(name, str) or name.count("{}") != 1 or not PLAIN_NAME.fullmatch(name.replace("{}", "x")):
            raise ValueError(f"model option name={name!r} must be a plain word holding '{{}}' once, e.g. 'ans{{}}'")
        metadata[NAME_PART] = name
    if choices is not None:
        metadata[CHOICES] = tuple(choices)
    return field(default=default, metadata=metadata)


def option_fields(options: type) -> dict[str, Field]:
    """A declared options class's fields (a dataclass type: `ModelConfig`'s shared ones, or a fusion's own), by name;
    `ModelConfig`'s `name` and `options` are not options a run sets."""
    return {f.name: f for f in fields(options) if not (options is ModelConfig and f.name in ("name", "options"))}


def _check_type(label: str, value, hint) -> None:
    """Raise a ValueError naming ``label`` when ``value`` is not of the field's annotation ``hint`` (bool, int,
    float — an int is accepted —, str, None, a Literal, or a union of them; any other annotation is not checked)."""
    import types
    import typing

    args = typing.get_args(hint) if typing.get_origin(hint) in (typing.Union, types.UnionType) else (hint,)
    what = []
    for arg in args:
        if arg is type(None) or arg is None:
            ok, text = value is None, "None"
        elif typing.get_origin(arg) is typing.Literal:
            ok, text = value in typing.get_args(arg), "one of " + ", ".join(map(repr, typing.get_args(arg)))
        elif arg is bool:
            ok, text = type(value) is bool, "true or false"
        elif arg is int:
            ok, text = type(value) is int, "an integer"
        elif arg is float:
            ok, text = type(value) in (int, float), "a number"
        elif arg is str:
            ok, text = isinstance(value, str), "a string"
        else:
            return
        if ok:
            return
        what.append(text)
    raise ValueError(f"{label}={value!r} must be " + " or ".join(what))


def check_model_options(options: type, values: dict, label: str = "ModelConfig"):
    """``options`` (a declared options class) built from ``values``: each value checked against its field's type and
    `model_option` choices, then the class's own ``check()`` (ranges, options that need one another); a ValueError
    names the field ('ModelConfig.eq1_words=...'). Unknown names are the caller's to refuse (`emml.models.model_config`
    names the model and its options)."""
    import typing

    declared = option_fields(options)
    try:
        hints = typing.get_type_hints(options)
    except Exception:  # an annotation that does not resolve (a plugin's): its values are checked by its check() only
        hints = {}
    for name, value in values.items():
        if name in hints:
            _check_type(f"{label}.{name}", value, hints[name])
        allowed = declared[name].metadata.get(CHOICES)
        if allowed is not None:
            check_choice(f"{label}.{name}", value, allowed)
    built = options(**values)
    check = getattr(built, "check", None)
    if callable(check):
        check()
    return built


@dataclass
class ModelConfig:
    """A model's configuration: the options every model shares (the encoders, the policy module, the diagnostic
    controls), declared here, and ``options``, those its fusion declares itself (`emml.models.Fusion.options`:
    Dual-Attention's ablations and opt-ins, PACMAN's window, a plugin's own), read through as attributes
    (``cfg.ga1`` is ``cfg.options.ga1``). Built by `emml.models.model_config` from a registry entry and
    `TrainConfig.model_options`."""

    name: str = "dual_attention"
    """Fusion architecture, one of `emml.models.ARCHITECTURES`: a fusion class of the model registry,
    emml/models/registry.py (ablations are its options)."""
    embed_dim: int = model_option(32)
    """Word-embedding size (paper appendix: 32)."""
    gru_text: int = model_option(32)
    """Hidden size of the sentence GRU (paper appendix: 32)."""
    hidden: int = model_option(128)
    """Hidden size of the policy's linear layer and GRU (paper appendix: 128)."""
    time_dim: int = model_option(32)
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
    sentence_activation: str = model_option("relu", name="xsent{}", choices=SENTENCE_ACTIVATIONS)
    """The activation on x_sent's Linear (§3: "the linear layer with ReLU activations"; "ReLU activations for
    sentence embedding ensure aggregation"): 'relu', the paper's, the default; or, opt-in, 'softplus', as
    non-negative but never 0, so that no gate channel can die. Measured in docs/fidelity.md (issue 34): under ReLU a
    channel whose pre-activation is negative for every question gets no gradient from the answer loss and its word
    can never be answered (seed 0: 'blue' with the last readout; 'torch', 'skullkey' and 'blue' with the mean)."""
    answer_gate_frames: int = model_option(0, name="warm{}")
    """The No Aux warm-up (issue 48, made one rule for every model by issue 61): for the run's first N frames the
    answer's gradient is kept off the image encoder (the conv) and every path from it, then the answer loss trains
    end to end as the paper has it; 0: off (the paper's loss from the start). Values are unchanged. Where the fusion
    has a GA2 gate (Dual-Attention), the answer loss keeps to that gate and x_sent; where it has none (the baselines,
    Dual-Attention w/o GA2), to its text side and answer head. Every fusion of the paper whose answer reads x_I takes
    it (`emml.models.Fusion.answer_warmup`); Text only's answer reads no image, and refuses it. Why: without aux
    labels, end to end from the start, the answer loss pins whole conv3 channels within ~100k frames (Dual-Attention,
    GA, FiLM: docs/fidelity.md, "No Aux"). The trainer sets it from the frames trained (`EmmlModel.at_frames`), so a
    resumed run resumes the schedule. Run name: 'warm<N>'."""
    x_image: str = model_option("sigmoid", choices=("sigmoid", "relu"))
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
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"ModelConfig.name={self.name!r} must be the name of a fusion architecture")
        for name in ("embed_dim", "gru_text", "hidden", "time_dim"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"ModelConfig.{name}={value!r} must be a positive integer (>= 1)")
        check_frames("ModelConfig.answer_gate_frames", self.answer_gate_frames)  # 0: off
        check_model_options(ModelConfig, {name: getattr(self, name) for name in option_fields(ModelConfig)})
        return self


SHARED_MODEL_OPTIONS: tuple[str, ...] = tuple(option_fields(ModelConfig))
"""The names `TrainConfig.model_options` may set for every model: the options `ModelConfig` declares. A model's
fusion declares more (`emml.models.Fusion.options`), checked where the model registry is read
(`emml.models.model_config`: where a run starts, a table is read, a model is built)."""


@dataclass
class TrainConfig:
    """One training run: environment, model, PPO and the run's own settings (issue: one trainer for all tables).

    Defaults are the paper's protocol (Appendix A); profiles in reproduce/profiles.toml change cost, not
    protocol, and every report states its profile."""

    model: str = "dual_attention"
    """Registry name of the model (`emml models`), ablations included."""
    aux: bool = False
    """Train with the auxiliary detection task (§3.2); turns on the env's aux labels."""
    seed: int = 0
    """Seeds Python, NumPy, torch and the envs (worker i gets seed + i)."""
    frames: int = 10_000_000
    """Agent steps to train, summed over actors (§5.1: 10M Easy, 50M Hard); at least one update (num_envs ×
    num_steps), and rounded up to whole updates (10M is 9,766 updates of 1,024: 10,000,384 frames)."""
    num_envs: int = 8
    """Parallel actors (Appendix A: 8)."""
    num_steps: int = 128
    """Rollout horizon per actor and update (Appendix A: 128)."""
    profile: str = "paper"
    """Name of the profile the run came from (smoke, demo, quick, paper), recorded everywhere."""
    eval_every: int = 0
    """Evaluate every this many frames for the curves; 0: only at the end."""
    eval_episodes: int = 100
    """Greedy evaluation episodes per (task, split) of the evaluations during training (the curves)."""
    final_eval_episodes: int = 500
    """Greedy evaluation episodes per (task, split) of the final evaluation, the score in results.json and the
    results table (paper silent). Larger than `eval_episodes`: one checkpoint's SGN train accuracy (GA quick seed
    0) ranged 0.51-0.71 over 18 disjoint blocks of 100 episodes, 0.54-0.61 over 5 blocks of 500 (docs/fidelity.md,
    "Trainer"); a score's binomial sd is ≤ 0.05 at 100 episodes, ≤ 0.022 at 500."""
    score: bool = True
    """Play the final evaluation and record the run's score (results.json, its results row). False: a measurement
    run (`emml bench train`'s temporary runs), trained and checkpointed only; an untrained agent's evaluation
    episodes run to the time limit and were most of a smoke bench's time."""
    diagnose_episodes: int = 20
    """SGN episodes behind the diagnostics logged at every evaluation (attention on target, detector AP; the actor's
    sensitivity reads 5× as many first steps: emml/eval/diagnose.py); 0: none."""
    checkpoint_every: int = 10
    """Write the checkpoint every this many updates (and at the end)."""
    log_every: int = 10
    """A log line every this many updates (metrics go to MLflow every update)."""
    answer_supervision: str = "eqa_steps"
    """Which steps train the answer cross-entropy: 'eqa_steps' (every step of an EQA episode: the correct answer
    is fixed for the episode) or 'answer_steps' (only steps where the agent answered). Paper silent."""
    device: str = "cpu"
    """'cpu' or 'cuda'."""
    precision: str = "fp32"
    """'fp32' (the paper's) or 'bf16': the conv stack's convolutions in bf16 in acting and the PPO update; the rest
    of the model, weights, losses and evaluation in fp32 (emml/rl/precision.py). bf16 is refused on a CPU
    without native bf16 arithmetic, where it runs slower."""
    compile: str = "off"
    """torch.compile the conv stack and the fusion unit (emml/rl/compiled.py): the same model within float
    tolerance, ~10-20 s of compiling at start, then faster (2-core CPU, end to end: x1.03 at 84x150, x1.23 at
    168x300; docs/throughput.md). 'on' (refused before any compute where it cannot run: a CPU without a C++
    compiler), 'off', or 'auto' (on where measured faster: a CPU with a C++ compiler; off on CUDA until measured
    there)."""
    cuda_graphs: bool = False
    """Acting and the PPO update replayed as CUDA graphs (emml/rl/graphs.py): the same computation, launched as one
    graph instead of hundreds of kernels per call. The paper's single batch only (`ppo.minibatches` = 1). On a CPU
    the same fixed-tensor calls run uncaptured (no faster; what the CPU tests compare with the plain path). Off by
    default until measured on a GPU (docs/throughput.md)."""
    threads: int = 0
    """torch threads; 0: all cores (the learner and the env workers take turns, PPO being synchronous)."""
    asynchronous: bool = True
    """Env workers in processes (True) or in the learner process (False, for debugging)."""
    env_groups: int = 2
    """Actors are stepped in this many groups, in turn: one group simulates while the policy acts for the next
    (double-buffered sampling; same algorithm, see emml/rl/sampler.py). 1: all actors in lockstep. Must divide
    num_envs."""
    envs_per_worker: int = 1
    """Envs hosted by each env worker process, stepped at once from one thread each (ViZDoom releases the GIL;
    `emml.envs.vector.GroupedDoomVectorEnv`): the same envs and seeds, fewer processes to wake at every step.
    Must divide num_envs / env_groups."""
    acting_threads: int = 1
    """torch threads while acting (batches of num_envs/env_groups, one step): one is about as fast as two for
    such small batches and leaves the other cores to the env workers; 0: as many as the learner."""
    max_engine_restarts: int = 3
    """An env worker restarts its engine when it dies (the episode in flight is dropped and counted); this many
    deaths in a row, less than `engine_restart_window` steps apart, end the run with an EngineError."""
    engine_restart_window: int = 1000
    """Steps of a worker after which an engine death no longer counts as repeated."""
    table: str = "adhoc"
    """MLflow experiment / results table the run belongs to."""
    run_root: str = "runs"
    """Where run directories (checkpoints, results.json) go, relative to the project root unless absolute."""
    results_root: str = "results"
    """Where finished runs are recorded as rows of `<table>/<profile>.csv` (small, committed), relative to the
    project root unless absolute."""
    env: DoomConfig = field(default_factory=DoomConfig)
    """The environment (its aux_labels follows `aux`): a HouseConfig when its difficulty is 'house'."""
    ppo: PPOConfig = field(default_factory=PPOConfig)
    """The PPO update's hyper-parameters (the paper's defaults)."""
    model_options: dict = field(default_factory=dict)
    """Overrides of the model's options: those every model shares (`ModelConfig`) and those its fusion declares
    (`emml.models.Fusion.options`); checked against the model's declared options where training starts
    (`emml.rl.hardware.check_runnable`, `emml.models.model_config`), before any compute."""

    RUNTIME: ClassVar[tuple[str, ...]] = (
        "frames",  # asking for more frames continues a run (finished or not) to the new target
        "eval_every",
        "eval_episodes",  # how a run is measured, not what it is: the evaluations' size
        "final_eval_episodes",
        "score",
        "diagnose_episodes",
        "checkpoint_every",
        "log_every",
        "threads",
        "asynchronous",
        "env_groups",  # how the actors are stepped, not what they do
        "envs_per_worker",
        "acting_threads",
        "max_engine_restarts",
        "engine_restart_window",
        "device",
        "compile",
        "cuda_graphs",
        "run_root",
        "results_root",
    )
    """How a run runs, not what it is: every other field is its identity (`identity`, emml/runs/rundir.py), which names
    its run dir and must match for a rerun to resume it."""

    def __post_init__(self):
        if self.ppo is None:  # callers that passed None for the defaults
            self.ppo = PPOConfig()
        self.env.aux_labels = self.aux

    def validate(self) -> TrainConfig:
        """The fields' values, before any compute. The model's registry entry and this machine are checked where
        training starts (`emml.rl.hardware.check_runnable`)."""
        if not isinstance(self.model, str) or not PLAIN_NAME.fullmatch(self.model):
            raise ValueError(f"model={self.model!r} must be a model registry name (`emml models`)")
        if not isinstance(self.model_options, dict):
            raise ValueError(f"model_options={self.model_options!r} must be a table of model option names to values")
        for key in self.model_options:
            if not isinstance(key, str) or not key.isidentifier() or key in ("name", "options"):
                raise ValueError(
                    f"model_options: {key!r} is not a model option name; the options every model shares: "
                    + ", ".join(SHARED_MODEL_OPTIONS)
                    + " (and its fusion's own, `emml models`)"
                )
        check_choice("env.difficulty", self.env.difficulty, ENV_DIFFICULTIES)
        self.env.validate()
        self.ppo.validate()
        check_choice("answer_supervision", self.answer_supervision, ("eqa_steps", "answer_steps"))
        check_device_name(self.device)
        positive = ("frames", "num_envs", "num_steps", "eval_episodes", "final_eval_episodes", "checkpoint_every")
        check_at_least(self, (*positive, "log_every"), 1)
        for name in ("frames", "eval_every"):
            check_frames(name, getattr(self, name))
        if "answer_gate_frames" in self.model_options:  # here too: it names the run dir (warm<N>), made after this
            check_frames("model_options.answer_gate_frames", self.model_options["answer_gate_frames"])
        if self.frames < self.frames_per_update:  # it used to be rounded up to one update, silently
            raise ValueError(
                f"frames={self.frames!r} is less than one update (num_envs × num_steps = {self.frames_per_update}); "
                f"the minimum is {self.frames_per_update}"
            )
        if self.seed < 0:
            raise ValueError(f"seed={self.seed!r} must be >= 0")
        for name in ("table", "profile"):  # they name folders and files: run_root/<table>/…, <table>/<profile>.csv
            value = getattr(self, name)
            if not isinstance(value, str) or not PLAIN_NAME.fullmatch(value):
                raise ValueError(
                    f"{name}={value!r} must be a plain name: letters, digits, '_', '.' or '-', starting with a letter "
                    "or digit (no path separators)"
                )
        if self.env_groups < 1 or self.num_envs % self.env_groups:
            raise ValueError(f"env_groups={self.env_groups!r} must be a positive divisor of num_envs={self.num_envs}")
        group = self.num_envs // self.env_groups
        if self.envs_per_worker < 1 or group % self.envs_per_worker:
            k = self.envs_per_worker
            raise ValueError(f"envs_per_worker={k!r} must be a positive divisor of num_envs / env_groups = {group}")
        if not isinstance(self.score, bool):
            raise ValueError(f"score={self.score!r} must be true or false")
        if self.compile not in COMPILE:
            raise ValueError(f"compile={self.compile!r}: allowed values are {', '.join(COMPILE)}")
        if not isinstance(self.cuda_graphs, bool):
            raise ValueError(f"cuda_graphs={self.cuda_graphs!r} must be true or false")
        if self.cuda_graphs and self.ppo.minibatches != 1:
            raise ValueError(
                f"cuda_graphs=true captures the paper's single batch: it needs ppo.minibatches=1, "
                f"got {self.ppo.minibatches} (or set cuda_graphs=false)"
            )
        if self.cuda_graphs and self.compile == "on" and self.device.startswith("cuda"):
            raise ValueError("cuda_graphs=true with compile='on' on CUDA is not measured: use compile='off' or 'auto'")
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision={self.precision!r}: allowed values are {', '.join(PRECISIONS)}")
        control = self.model_options.get("control", "none")
        if control == "type_gate":
            raise ValueError(
                "model_options.control='type_gate' is an evaluation control: apply it to a trained checkpoint "
                "(emml eval CKPT --control type_gate, emml diagnose CKPT --control type_gate)"
            )
        if control != "none" and not self.aux:
            raise ValueError(f"model_options.control={control!r} reads the aux labels: it needs aux=True")
        counts = ("eval_every", "diagnose_episodes", "threads", "acting_threads", "max_engine_restarts")
        check_at_least(self, (*counts, "engine_restart_window"), 0)
        return self

    @property
    def frames_per_update(self) -> int:
        """Derived: num_envs × num_steps (1,024 under the paper's protocol)."""
        return self.num_envs * self.num_steps

    @property
    def num_updates(self) -> int:
        """Derived: updates to reach `frames` (rounded up)."""
        return -(-self.frames // self.frames_per_update)

    def identity(self) -> dict:
        """`to_dict` less the `RUNTIME` fields: what the run is (emml/runs/rundir.py names and resumes runs by it)."""
        return {k: v for k, v in self.to_dict().items() if k not in self.RUNTIME}

    def to_dict(self) -> dict:
        d = asdict(self)
        d["ppo"] = asdict(self.ppo)
        return d

    @classmethod
    def from_dict(cls, values: dict) -> TrainConfig:
        """Inverse of to_dict (unknown keys are rejected by name)."""
        values = dict(values)
        env_values = values.pop("env", {})
        env = config_from_dict(env_config_class(env_values.get("difficulty", "easy")), env_values)
        ppo = config_from_dict(PPOConfig, values.pop("ppo", {}) or {})
        cfg = config_from_dict(cls, {k: v for k, v in values.items()})
        cfg.env, cfg.ppo = env, ppo
        cfg.env.aux_labels = cfg.aux
        return cfg


def apply_overrides(cfg: TrainConfig, overrides: dict, source: str = "--set") -> TrainConfig:
    """Set fields by dotted name ('frames', 'env.height', 'ppo.lr', 'model_options.state_temperature'); an unknown
    name or a value of the wrong type fails naming ``source`` (the --set option, or the profile it came from), the
    field and what it accepts. A model option's name and value are checked against its model's declared options
    where the model registry is read (`emml.models.model_config`: where training starts, a table is read)."""
    for key, value in overrides.items():
        target, name = cfg, key
        if "." in key:
            section, name = key.split(".", 1)
            if section not in ("env", "ppo", "model_options"):
                raise ValueError(f"{source} {key!r}: section {section!r} is not one of 'env', 'ppo', 'model_options'")
            if section == "model_options":  # its name and value: the model registry's check (`validate`)
                if not name.isidentifier() or name in ("name", "options"):
                    raise ValueError(
                        f"{source} {key!r}: not a model option name; the options every model shares: "
                        + ", ".join(SHARED_MODEL_OPTIONS)
                        + " (and its fusion's own, `emml models`)"
                    )
                cfg.model_options = {**cfg.model_options, name: value}
                continue
            target = getattr(cfg, section)
        known = [f.name for f in fields(target)]
        if name not in known:
            raise ValueError(f"{source} {key!r}: unknown field; known: {', '.join(known)}")
        setattr(target, name, _typed(value, getattr(target, name), f"{source} {key!r}"))
    cfg.env = match_env_class(cfg.env)
    cfg.env.aux_labels = cfg.aux
    return cfg


def _typed(value, current, where: str):
    """``value`` checked against the type of the field's current value (an int is accepted for a float)."""
    if current is None or isinstance(current, (tuple, list, dict)):
        return value
    if isinstance(current, bool):
        ok, what = type(value) is bool, "true or false"
    elif isinstance(current, int):
        ok, what = type(value) is int, "an integer"
    elif isinstance(current, float):
        ok, what = type(value) in (int, float), "a number"
        value = float(value) if ok else value
    elif isinstance(current, str):
        ok, what = isinstance(value, str), "a string"
    else:
        return value
    if not ok:
        raise ValueError(f"{where}: expected {what}, got {value!r}")
    return value
