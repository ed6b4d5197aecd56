"""The paper's visualisations on any checkpoint (issue 13): what each conv3 channel detects beside its aux label
(the channel figure), and over one episode the frame, the spatial attention x_spat, the answer distribution x_Ans
and the action taken (the attention figure); plus a captioned GIF per episode.

Every plotted array is the model's own output, recorded while the episode is played (`record_episode`); nothing
is recomputed for the figure. Both figures are made at a page's text width (7 in, emml/report/savefig.py's
`PAGE_INCHES`) in the reports' style (7-9 pt text), their long titles wrapped to it: printed at that width, nothing is
scaled down or cut off (issue 63).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

from emml.runs.atomic import replacing
from emml.runs.diskspace import RERUN

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from emml.config.schema import DoomConfig  # noqa: E402
from emml.envs.doom import MOVES  # noqa: E402
from emml.eval.evaluate import obs_to_torch, playing  # noqa: E402
from emml.report.savefig import PAGE_HEIGHT_INCHES, PAGE_INCHES, save, wrap  # noqa: E402

CHANNEL_WORDS = ("red", "green", "torch", "pillar", "smallest", "tall", "armor")
"""The rows of the channel figure: colours, objects, a size word and a superlative (no aux label exists for it)."""


@dataclass
class Episode:
    """One greedy episode as the model saw and answered it; step arrays are the model's outputs at that step."""

    sentence: str
    task: str
    words: tuple[str, ...]
    x_sent: np.ndarray
    """(V,) x_sent as the fusion reads it (Section 3; Eq. 4's gate in Dual-Attention), per vocabulary channel; zeros
    for a model without one."""
    x_sent_source: str = "x_sent"
    """'x_sent' (the sentence encoder's), 'type_gate' (the control's word-type gate, emml/models/type_gate.py, in
    its place) or 'none' (the model has no sentence representation)."""
    frames: list[np.ndarray] = field(default_factory=list)
    """(H, W, 3) uint8 per step."""
    attention: list[np.ndarray] = field(default_factory=list)
    """(h, w) x_spat per step (Dual-Attention; empty for models without spatial attention)."""
    answers: list[np.ndarray] = field(default_factory=list)
    """(V,) x_Ans = softmax of the answer logits per step."""
    channels: list[np.ndarray] = field(default_factory=list)
    """(V, h, w) sigmoid of the conv3 output per step (the aux predictions)."""
    labels: list[np.ndarray] = field(default_factory=list)
    """(V, h, w) aux labels per step (empty when the env has none)."""
    moves: list[int] = field(default_factory=list)
    answer_word: int = -1
    """The answer word taken with the last move (EQA)."""
    success: bool = False
    tokens: np.ndarray | None = None


@torch.no_grad()
def record_episode(model, env_cfg: DoomConfig, task: str = "sgn", seed: int = 0, device="cpu") -> Episode:
    """Play one greedy episode of ``task`` (train split) and record the model's outputs at every step."""
    cfg = dataclasses.replace(
        env_cfg, tasks=task, split="train", aux_labels=True, target_in_obs=True, instructions=None
    )
    with playing(model, cfg) as (env,):
        obs, _ = env.reset(seed=seed)
        x_sent = model.sentence_gate(torch.as_tensor(obs["tokens"])[None].to(device))  # what Eq. 4 reads
        control = getattr(model.cfg, "control", "none")
        ep = Episode(
            sentence=env.episode.sentence.text,
            task=task,
            words=tuple(env.vocab.words),
            x_sent=np.zeros(len(env.vocab)) if x_sent is None else x_sent[0].cpu().numpy(),
            x_sent_source="none" if x_sent is None else ("type_gate" if control == "type_gate" else "x_sent"),
            tokens=obs["tokens"].copy(),
        )
        state = model.initial_state(1, device)
        start = torch.ones(1, 1, dtype=torch.bool, device=device)
        done, info = False, {}
        while not done:
            out, state = model(obs_to_torch({k: np.asarray(v)[None] for k, v in obs.items()}, device), state, start)
            start = torch.zeros_like(start)
            ep.frames.append(np.ascontiguousarray(obs["image"].transpose(1, 2, 0)))
            ep.labels.append(obs["aux"])
            ep.channels.append(torch.sigmoid(out.aux_logits[0, 0]).cpu().numpy())
            ep.answers.append(torch.softmax(out.answer_logits[0, 0], -1).cpu().numpy())
            if out.attention is not None:
                ep.attention.append(out.attention[0, 0].cpu().numpy())
            move = int(out.logits[0, 0].argmax())
            word = int(out.answer_logits[0, 0].argmax())
            ep.moves.append(move)
            ep.answer_word = word
            obs, _, terminated, truncated, info = env.step(np.array([move, word]))
            done = terminated or truncated
        ep.success = bool(info.get("success"))
    return ep


def attention_figure(ep: Episode, path: str | Path, rows: int = 6) -> plt.Figure:
    """The attention figure: on top x_sent per vocabulary channel, as in the paper's attention visualization (the
    sentence's words in purple); then ``rows`` steps spread over the episode, each with the frame, the frame under
    x_spat, the top answers of x_Ans, and the action taken."""
    steps = np.unique(np.linspace(0, len(ep.frames) - 1, min(rows, len(ep.frames))).round().astype(int))
    frame_h, frame_w = ep.frames[0].shape[:2]
    step_inches = 0.45 + PAGE_INCHES * 0.36 * frame_h / frame_w  # a frame panel's height at its share of the width
    step_inches = min(step_inches, (PAGE_HEIGHT_INCHES - 1.6) / len(steps))  # lower frames: the figure fits a page
    fig = plt.figure(figsize=(PAGE_INCHES, 1.6 + step_inches * len(steps)), layout="constrained")
    grid = fig.add_gridspec(
        len(steps) + 1, 3, width_ratios=[1.6, 1.6, 1.2], height_ratios=[1.6] + [step_inches] * len(steps)
    )
    top = fig.add_subplot(grid[0, :])
    in_sentence = set(ep.sentence.split())
    colours = ["tab:purple" if w in in_sentence else "tab:gray" for w in ep.words]
    top.bar(range(len(ep.words)), ep.x_sent, color=colours)  # every channel: a ReLU zeroes many of them
    top.set_xticks(range(len(ep.words)), ep.words, rotation=60)
    outcome = "success" if ep.success else "failure"
    shown = {"x_sent": "x_sent per channel", "type_gate": "the type_gate control's gate per channel (x_sent's place)"}
    what = shown.get(ep.x_sent_source, "no x_sent in this model")
    title = f"{ep.task.upper()} '{ep.sentence}' ({outcome}, {len(ep.frames)} steps): {what}"
    top.set_title(wrap(title, PAGE_INCHES - 0.2, plt.rcParams["axes.titlesize"]))
    for r, t in enumerate(steps, start=1):
        frame = ep.frames[t]
        ax = fig.add_subplot(grid[r, 0])
        ax.imshow(frame)
        ax.set_title(f"t={t}: {MOVES[ep.moves[t]]}")
        ax.axis("off")
        ax = fig.add_subplot(grid[r, 1])
        ax.imshow(frame)
        if ep.attention:
            h, w = frame.shape[:2]
            im = ax.imshow(
                ep.attention[t], cmap="inferno", alpha=0.6, extent=(0, w, h, 0), interpolation="nearest", vmin=0
            )
            fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02, label="x_spat")
            ax.set_title(f"x_spat (max {ep.attention[t].max():.2f})")
        else:
            ax.set_title("no spatial attention in this model")
        ax.axis("off")
        ax = fig.add_subplot(grid[r, 2])
        best = np.argsort(ep.answers[t])[::-1][:5]
        ax.barh(range(len(best))[::-1], ep.answers[t][best], color="tab:green")
        ax.set_yticks(range(len(best))[::-1], [ep.words[i] for i in best])
        ax.set_xlim(0, 1)
        ax.set_title("x_Ans (top 5)")
    save(fig, path)
    return fig


def channels_figure(
    models: list[tuple[str, object]],
    env_cfg: DoomConfig,
    path: str | Path,
    seed: int = 0,
    device="cpu",
    words: tuple[str, ...] = CHANNEL_WORDS,
) -> tuple[plt.Figure, np.ndarray, dict[str, np.ndarray]]:
    """The channel figure on the first frame of an Easy SGN episode: a row per word, with the aux label, each
    model's conv3 channel for the word (sigmoid), and the frame. Returns the figure, the labels and the channels
    (name → (V, h, w)) it plotted."""
    episodes = {name: record_episode(m, env_cfg, "sgn", seed, device) for name, m in models}
    first = next(iter(episodes.values()))
    labels, frame = first.labels[0], first.frames[0]
    channels = {name: ep.channels[0] for name, ep in episodes.items()}
    words = tuple(w for w in words if w in first.words)  # a run on the training vocabulary (Table 4) lacks some
    cols = 2 + len(models)
    h, w = frame.shape[:2]
    panel = (PAGE_INCHES - 1.2) / cols  # a panel's width: the page's, less the words' column and the colour scale
    row = min(0.15 + panel * h / w, (PAGE_HEIGHT_INCHES - 0.7) / max(len(words), 1))  # smaller maps: fits a page
    fig, axes = plt.subplots(
        len(words), cols, figsize=(PAGE_INCHES, 0.7 + len(words) * row), squeeze=False,
        layout="constrained",
    )  # fmt: skip
    for r, word in enumerate(words):
        v = first.words.index(word)
        panels = [("aux label", labels[v])] + [(name, channels[name][v]) for name in channels]
        for c, (title, arr) in enumerate(panels):
            ax = axes[r, c]
            im = ax.imshow(arr, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
            # a model's label names its run ('no aux (dual_attention-easy-noaux-…)'): wrapped to its panel
            ax.set_title(wrap(title, panel, plt.rcParams["axes.titlesize"]) if r == 0 else "")
            ax.set_xticks([]), ax.set_yticks([])
            ax.spines[:].set_visible(True)  # a frame round every map: a white (all 1) channel is not a blank
        axes[r, 0].set_ylabel(word)
        axes[r, -1].imshow(frame)
        axes[r, -1].set_title("frame" if r == 0 else "")
        axes[r, -1].axis("off")
    title = f"conv3 channels and aux labels, '{first.sentence}' (first frame)"
    fig.suptitle(wrap(title, PAGE_INCHES - 0.2, plt.rcParams["figure.titlesize"]))
    scale = wrap("aux label / sigmoid(conv3): 0 black, 1 white", 3, plt.rcParams["axes.labelsize"])
    fig.colorbar(im, ax=axes, shrink=0.8, label=scale)
    save(fig, path)
    return fig, labels, channels


def episode_gif(ep: Episode, path: str | Path) -> Path:
    """A captioned GIF of the episode: the sentence, each step's action, and the outcome at the end."""
    from emml.report.oracle_video import _captioned

    answer = f" -> {ep.words[ep.answer_word]}" if ep.task == "eqa" and ep.moves[-1] == MOVES.index("answer") else ""
    images = [_captioned(f, f"{ep.sentence} | t={t} {MOVES[m]}") for t, (f, m) in enumerate(zip(ep.frames, ep.moves))]
    images += [_captioned(ep.frames[-1], f"{ep.sentence}{answer}: {'success' if ep.success else 'failure'}")] * 5
    with replacing(path, then=RERUN) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=150, loop=0)
    return Path(path)
