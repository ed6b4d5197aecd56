"""What the paper fixes, and where it is silent but our choice changes what a run learns: one declared list, compared
with a run's saved config (`TrainConfig.to_dict()`, kept in its results.json) so that every report states the
deviations in force for the runs it shows (emml/report/deviations.py), never a hand-written list.

Pure Python at import (no torch): `resolve` looks the model's options up in emml.models only when called.
Sources name the paper's passages: "App. A" (hyperparameters), "§5.1" (the Doom training protocol), "App. C" (the
House), "Eq. N" (the Dual-Attention unit), "'Auxiliary Task'" (the paragraph of that name).
"""

from __future__ import annotations

import copy
import functools
from collections.abc import Callable
from dataclasses import dataclass, fields

from emml.config.env_kinds import ENV_KINDS

PAPER_FRAMES = {k.name: k.paper_frames for k in ENV_KINDS.values()}
"""§5.1: 10M frames in Easy, 50M in Hard; App. C: 50M in the House (emml/config/env_kinds.py)."""
PAPER_MAX_STEPS = {k.name: k.paper_max_steps for k in ENV_KINDS.values()}
"""§5.1: episodes of at most 210 steps; App. C: 420 in the House (emml/config/env_kinds.py)."""


WARMUP = "answer kept off the image encoder"
"""The label of the No Aux warm-up's deviation (`ModelConfig.answer_gate_frames`, issue 61): the reports state it once
per table with the rows it applies to (emml/report/deviations.py, `noaux_schedule`)."""


def count(n) -> str:
    """1500000 → '1.5M', 163840 → '163,840', 512 → '512'."""
    n = int(n)
    if n >= 1_000_000 and n % 100_000 == 0:
        return f"{n / 1_000_000:g}M"
    return f"{n:,}"


def _plain(value) -> str:
    if isinstance(value, bool):
        return "on" if value else "off"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


@dataclass(frozen=True)
class PaperValue:
    """A setting the paper states: a run whose value differs deviates from the paper."""

    label: str
    """How a caption names it ('input', 'frames')."""
    fields: tuple[str, ...]
    """Dotted fields of the resolved config (`resolve`): 'env.height', 'ppo.lr', 'model.state_scale'."""
    paper: Callable[[dict], tuple]
    """The paper's values of `fields` for a run (resolved config → values; frames depend on the difficulty)."""
    source: str | Callable[[dict], str]
    """Where the paper states it (resolved config → text where it depends on the run)."""
    show: Callable[[tuple], str] = lambda v: " / ".join(map(_plain, v))
    """Values → text ('84×150')."""
    applies: Callable[[dict], bool] = lambda c: True
    """Whether the setting exists for a run (x_S of Dual-Attention, aux labels of an aux run)."""

    def deviation(self, cfg: dict) -> str | None:
        """'input 84×150 (paper 168×300, App. A)', or None when the run follows the paper here."""
        if not self.applies(cfg):
            return None
        ours, paper = tuple(cfg[f] for f in self.fields), self.paper(cfg)
        if ours == paper:
            return None
        source = self.source(cfg) if callable(self.source) else self.source
        return f"{self.label} {self.show(ours)} (paper {self.show(paper)}, {source})"


@dataclass(frozen=True)
class OurChoice:
    """A point where the paper is silent (or contradicts itself) and the value changes what a run learns: stated for
    every run it applies to, with the run's value."""

    label: str
    """How a caption names it."""
    fields: tuple[str, ...]
    """Dotted fields of the resolved config."""
    note: str
    """What the paper says (or does not)."""
    show: Callable[[tuple, dict], str] = lambda v, c: " / ".join(map(_plain, v))
    """(values, resolved config) → text."""
    applies: Callable[[dict], bool] = lambda c: True
    """Whether the point exists for a run."""

    def statement(self, cfg: dict) -> str | None:
        """'wrong-object/answer reward 0 (paper silent: …)', or None when the point does not apply to the run."""
        if not self.applies(cfg):
            return None
        return f"{self.label} {self.show(tuple(cfg[f] for f in self.fields), cfg)} ({self.note})"


def _spatial_map(cfg: dict) -> bool:
    """Dual-Attention with its spatial map (every variant but w/o SA): x_S is the map of Eq. 2."""
    return cfg["model.name"] == "dual_attention" and cfg["model.spatial_attention"]


def _protocol(cfg: dict) -> str:
    """Where the paper gives a run's training protocol: §5.1 for Doom, App. C for the House."""
    return ENV_KINDS[cfg["env.difficulty"]].source


def _x_s(v: tuple) -> str:
    return "h·w·vec(x_spat)" if v[0] else "vec(x_spat)"


def _aux_words(v: tuple, cfg: dict) -> str:
    """The aux labels' words against the default: every vocabulary word but the dataset's superlatives."""
    from emml.tasks.language import load_dataset, resolve_vocabulary

    words, vocabulary = v
    dataset = load_dataset(cfg["env.dataset"])
    vocab = resolve_vocabulary(vocabulary, dataset).words
    superlatives = set(dataset.word_groups["superlatives"])
    default = [w for w in vocab if w not in superlatives]
    if words is None or list(words) == default:
        return f"for {len(default)} of {len(vocab)} words: all but the superlatives, function words all-zero"
    return f"for {len(words)} of {len(vocab)} words: {', '.join(words)}; function words all-zero"


PAPER: tuple[PaperValue, ...] = (
    PaperValue("input", ("env.height", "env.width"), lambda c: (168, 300), "App. A", lambda v: f"{v[0]}×{v[1]}"),
    PaperValue(
        "frames",
        ("frames",),
        lambda c: (PAPER_FRAMES[c["env.difficulty"]],),
        _protocol,
        lambda v: count(v[0]),
    ),
    PaperValue(
        "actors × horizon",
        ("num_envs", "num_steps"),
        lambda c: (8, 128),
        "App. A",
        lambda v: f"{v[0]} × {v[1]}",
    ),
    PaperValue(
        "episode limit",
        ("env.max_steps",),
        lambda c: (PAPER_MAX_STEPS[c["env.difficulty"]],),
        _protocol,
        lambda v: f"{v[0]} steps",
    ),
    PaperValue(
        "rewards",
        ("env.success_reward", "env.step_reward"),
        lambda c: (1.0, -0.001),
        "§5.1",
        lambda v: f"{v[0]:+g} success, {v[1]:g} per step",
    ),
    PaperValue("reward shaping", ("env.shaping",), lambda c: (True,), "§5.1"),
    PaperValue("PPO clip", ("ppo.clip_coef",), lambda c: (0.2,), "App. A"),
    PaperValue("PPO epochs", ("ppo.epochs",), lambda c: (4,), "App. A"),
    PaperValue("PPO minibatches", ("ppo.minibatches",), lambda c: (1,), "App. A: a single batch"),
    PaperValue("discount", ("ppo.gamma",), lambda c: (0.99,), "App. A"),
    PaperValue("learning rate", ("ppo.lr",), lambda c: (2.5e-4,), "App. A"),
    PaperValue("word embedding / GRU", ("model.embed_dim", "model.gru_text"), lambda c: (32, 32), "App. A"),
    PaperValue("policy hidden size", ("model.hidden",), lambda c: (128,), "App. A"),
    PaperValue(
        "PACMAN window",
        ("model.pacman_frames",),
        lambda c: (5,),
        "App. A, 'Baseline details'",
        lambda v: f"{v[0]} frames",
        lambda c: c["model.name"] == "pacman",
    ),
    PaperValue("x_S =", ("model.state_scale",), lambda c: (False,), "text after Eq. 5", _x_s, _spatial_map),
    PaperValue(
        "x_S read at temperature",
        ("model.state_temperature",),
        lambda c: (None,),
        "Eq. 2's map as is",
        lambda v: "1" if v[0] is None else f"{v[0]:g} (gradient stopped)",
        _spatial_map,
    ),
    PaperValue(
        "x_sent read from",
        ("model.sentence_readout",),
        lambda c: ("last",),
        "§3: 'a GRU followed by a linear layer', its final state",
        lambda v: {"last": "the GRU's last output", "mean": "the mean of the GRU's outputs"}.get(v[0], v[0]),
        lambda c: c["model.name"] != "image_only",
    ),
    PaperValue(
        "x_sent activation",
        ("model.sentence_activation",),
        lambda c: ("relu",),
        "§3: 'the linear layer with ReLU activations'",
        lambda v: {"relu": "ReLU", "softplus": "softplus (never 0)"}.get(v[0], v[0]),
        lambda c: c["model.name"] != "image_only",
    ),
    PaperValue(
        "baseline answer head",
        ("model.answer_activation",),
        lambda c: ("relu",),
        "App. 'Baseline details': 'a linear layer f with ReLU activations followed by softmax'",
        lambda v: {"relu": "softmax(ReLU(Linear(x_S)))", "softplus": "softmax(softplus(Linear(x_S))) (never 0)"}.get(
            v[0], v[0]
        ),
        lambda c: "model.answer_activation" in c,
    ),
    PaperValue(
        "Eq. 1 gates with",
        ("model.eq1_words",),
        lambda c: ("all",),
        "§3.1: x_BoW of every word of the text",
        lambda v: {"all": "every word", "content": "the content words only (function words out)"}.get(v[0], v[0]),
        lambda c: c["model.name"] == "dual_attention" and c["model.ga1"],
    ),
    PaperValue(
        "answer loss trains",
        ("model.answer_grad",),
        lambda c: ("all",),
        "§3: Eq. 1-5 trained end to end",
        lambda v: {
            "all": "the conv and x_sent",
            "gate": "x_sent only (x_SA's gradient stopped in Eq. 4)",
            "centered": "the conv and x_sent, its gradient into x_I centred over the cells (Eq. 3)",
        }.get(v[0], v[0]),
        lambda c: c["model.name"] == "dual_attention" and c["model.ga2"],
    ),
    PaperValue(
        WARMUP,
        ("model.answer_gate_frames",),
        lambda c: (0,),
        "§3 and App. 'Baseline details': every model trained end to end",
        lambda v: f"for the first {v[0]:,} frames, then end to end" if v[0] else "never",
    ),
    PaperValue(
        "aux loss",
        ("ppo.aux_balance",),
        lambda c: ("none",),
        "'Auxiliary Task': 'trained with cross-entropy loss'",
        lambda v: {"none": "cross-entropy over every cell", "word": "cross-entropy balanced per word"}.get(v[0], v[0]),
        lambda c: c["aux"],
    ),
    PaperValue(
        "diagnostic control",
        ("model.control",),
        lambda c: ("none",),
        "not the paper's model",
        lambda v: "none" if v[0] == "none" else f"'{v[0]}' (privileged labels)",
    ),
)
"""Every setting the paper states that a config can change, with where it states it."""

CHOICES: tuple[OurChoice, ...] = (
    OurChoice(
        "wrong-object/answer reward",
        ("env.wrong_reward",),
        "paper silent: §5.1 names only +1 and -0.001 per step",
    ),
    OurChoice(
        "shaping",
        ("env.shaping_coef",),
        "paper: 'a small reward proportional to the decrease in distance', §5.1",
        lambda v, c: f"{v[0]:g} per map unit",
        lambda c: c["env.shaping"],
    ),
    OurChoice(
        "aux labels",
        ("env.aux_words", "env.vocabulary"),
        "paper silent on function words, 'Auxiliary Task'",
        _aux_words,
        lambda c: c["aux"],
    ),
    OurChoice(
        "aux label cells:",
        ("env.label_grid",),
        "paper silent",
        lambda v, c: {"receptive_field": "conv3 receptive-field centres", "even": "an even partition of the frame"}[
            v[0]
        ],
        lambda c: c["aux"],
    ),
    OurChoice(
        "x_I =",
        ("model.x_image",),
        "paper: sigmoid in App. A, ReLU in the text after Eq. 2",
        lambda v, c: f"{v[0]}(conv3)",
    ),
    OurChoice("frame skip", ("env.frame_skip",), "paper silent", lambda v, c: f"{v[0]} tics a step"),
    OurChoice(
        "answer loss on",
        ("answer_supervision",),
        "paper silent: §3.2 'a supervised cross-entropy loss'",
        lambda v, c: {"eqa_steps": "every step of an EQA episode", "answer_steps": "the answering step only"}.get(
            v[0], v[0]
        ),
        lambda c: c["env.tasks"] != "sgn",
    ),
    OurChoice(
        "score:",
        ("score_episodes",),
        "paper silent on its evaluation size",
        lambda v, c: f"greedy, {v[0]:,} episodes per task and split",
    ),
    OurChoice(
        "precision",
        ("precision",),
        "paper silent; fp32 elsewhere",
        lambda v, c: f"{v[0]} convolutions",
        lambda c: c["precision"] != "fp32",
    ),
)
"""The points where the paper is silent or contradicts itself and our choice matters (docs/fidelity.md)."""


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for key, value in d.items():
        if isinstance(value, dict) and key in ("env", "ppo"):
            out.update(_flatten(value, f"{key}."))
        else:
            out[prefix + key] = value
    return out


@functools.cache
def _defaults(difficulty: str) -> dict:
    """TrainConfig's defaults for an env kind, flattened: built once per kind, not once per run a report shows
    (issue 64); `resolve` reads a copy."""
    from emml.config.schema import TrainConfig, env_config_class

    return _flatten(TrainConfig(env=env_config_class(difficulty)()).to_dict())


def resolve(saved: dict) -> dict:
    """A saved config (`TrainConfig.to_dict()`, possibly from an older version) flattened to dotted fields, with the
    fields it predates at today's defaults and the model's effective options under 'model.*' (its registry entry
    and overrides, emml.models.model_config). 'score_episodes': the final evaluation's episodes
    (`final_eval_episodes`, or `eval_episodes` for a run saved before that field existed)."""
    from emml.models import model_config

    env = saved.get("env", {})
    cfg = {**copy.deepcopy(_defaults(env.get("difficulty", "easy"))), **_flatten(saved)}
    options = dict(saved.get("model_options") or {})
    model = model_config(cfg["model"], **options)
    cfg.update({f"model.{f.name}": getattr(model, f.name) for f in fields(model) if f.name != "options"})
    cfg.update({f"model.{f.name}": getattr(model.options, f.name) for f in fields(model.options)})  # its fusion's
    cfg["score_episodes"] = saved.get("final_eval_episodes", saved.get("eval_episodes", cfg["eval_episodes"]))
    return cfg


def deviations(cfg: dict, skip: frozenset[str] = frozenset()) -> list[str]:
    """The run's deviations from the paper (resolved config); settings whose fields are all in ``skip`` (the
    overrides that define the table row, e.g. 'w/o Reward Shaping') are the experiment, not a deviation."""
    out = []
    for p in PAPER:
        if set(p.fields) <= skip:
            continue
        line = p.deviation(cfg)
        if line is not None:
            out.append(line)
    return out


def choices(cfg: dict) -> list[str]:
    """Our choices in force for the run where the paper is silent."""
    return [s for c in CHOICES if (s := c.statement(cfg)) is not None]


def answer_reads_image(model: str) -> bool:
    """Whether a registered model's answer reads the image (its No Aux runs take issue 61's warm-up; Text only's
    does not): the registry's own flag, for the reports, which do not import the model zoo."""
    from emml.models import MODELS

    return bool(MODELS[model].fusion.answer_warmup)
