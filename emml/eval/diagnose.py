"""What a researcher looks at when a variant does not learn SGN (issue 12): three numbers, at every evaluation and
for any checkpoint (`emml diagnose CHECKPOINT`).

* ``attention_on_target`` — on SGN frames that show the referent, how often the argmax of the spatial attention
  x_spat (Eq. 2) falls on one of its cells; ``attention_mass_on_target`` — the mass x_spat puts there. Dual-Attention
  only (None for models without a spatial map).
* ``detector_ap`` — per supervised word, the average precision of the conv3 channel sigmoid(conv3)[w] against the
  aux labels (§3.2) over every cell of those frames; the mean over words that occur, and each word's.
* ``actor_sensitivity`` — in Easy, how much the first move distribution pi(a_0 | I_0, T) depends on where the
  referent stands: the largest total-variation distance between the mean step-0 move distributions of two target
  slots. An actor that ignores x_S scores ~0 (the noise floor of `step0_episodes` episodes); one that turns toward
  the target scores up to 1.
* ``x_image_saturated`` — the fraction of conv3 channels whose x_I is pinned on every cell of every frame, so that
  no gradient passes (issue 48: without the aux task the conv collapsed to a constant code): under the sigmoid of
  Appendix A, |z| > `SATURATED_LOGIT` everywhere; under the ReLU of §3.1, z <= 0 everywhere (a dead channel);
  ``x_image_spatial_std`` — the spatial std of x_I per frame, the mean over frames and channels (0: x_I says nothing
  of where anything is, and Eq. 2's map is uniform). Each channel's under ``x_image_channels``. Both count collapse
  only (issue 61): in a run with aux labels, the channels of the words whose labels are all zero (the function words,
  'go', 'the', 'what', ...: they describe no object) are trained to 0 by the aux loss, pinned as they should be, and
  not counted; ``x_image_counted`` names the words counted, ``x_image_uncounted`` those left out.

Frames come from the model's own sampled actions (a seeded generator), so that the views are the ones it meets
in training; the referent's cells come from the env's privileged label buffer.
"""

from __future__ import annotations

import dataclasses
from itertools import combinations

import numpy as np
import torch

from emml.config.env_kinds import ENV_KINDS
from emml.config.schema import X_IMAGES, DoomConfig
from emml.envs.doom import DoomEnv
from emml.eval.evaluate import eval_settings, obs_to_torch, playing


def average_precision(scores: np.ndarray, labels: np.ndarray) -> float:
    """AP of ranking ``scores`` against binary ``labels``: the mean precision at each positive (nan if none)."""
    labels = labels.astype(bool).ravel()
    positives = int(labels.sum())
    if positives == 0:
        return float("nan")
    order = np.argsort(-scores.ravel(), kind="stable")
    hits = labels[order]
    precision_at = np.cumsum(hits) / np.arange(1, hits.size + 1)
    return float(precision_at[hits].sum() / positives)


SATURATED_LOGIT = 6.0
"""|z| above which sigmoid(z) counts as pinned: sigmoid'(6) = 0.0025, a gradient ~1/100 of its value at 0."""
SATURATION_WARNING = 0.5
"""The trainer warns in its log when at least this fraction of the channels is pinned (`x_image_saturated`)."""


def _sigmoid(z: np.ndarray) -> np.ndarray:
    """1 / (1 + exp(-z)), the same values, without numpy's 'overflow encountered in exp' where a saturated channel's
    exp(-z) overflows to inf (the result is 0 there, as it should be; scipy's expit differs by 1 ulp and would reorder
    near-ties in the detector AP)."""
    with np.errstate(over="ignore"):
        return 1.0 / (1.0 + np.exp(-z))


def x_image_saturation(logits: np.ndarray, x_image: str = "sigmoid", counted: np.ndarray | None = None) -> dict:
    """How far x_I is from a constant code, on conv3 logits z of real frames (F, V, h, w), under the model's
    ``x_image`` ('sigmoid' or 'relu', `ModelConfig.x_image`): the fraction of the ``counted`` channels (bool (V,);
    None: all) pinned on every cell of every frame (sigmoid: |z| > SATURATED_LOGIT; relu: z <= 0), their mean spatial
    std of x_I, and each channel's figures (index → {"pinned", "spatial_std", "mean", "counted"})."""
    z = np.asarray(logits, dtype=np.float64)
    if z.ndim != 4 or z.shape[0] == 0:
        raise ValueError(f"x_image_saturation: logits must be (frames, V, h, w) with frames >= 1, got {z.shape}")
    counted = np.ones(z.shape[1], dtype=bool) if counted is None else np.asarray(counted, dtype=bool)
    if counted.shape != (z.shape[1],) or not counted.any():
        raise ValueError(f"x_image_saturation: counted must be a bool ({z.shape[1]},) mask of at least one channel")
    if x_image == "sigmoid":
        pinned, x = (np.abs(z) > SATURATED_LOGIT).all(axis=(0, 2, 3)), _sigmoid(z)
    elif x_image == "relu":
        pinned, x = (z <= 0).all(axis=(0, 2, 3)), np.maximum(z, 0.0)
    else:
        raise ValueError(f"x_image={x_image!r} is unknown; allowed: {', '.join(X_IMAGES)}")
    spatial_std = x.reshape(*x.shape[:2], -1).std(-1).mean(0)  # (V,): per frame over cells, then over frames
    channels = {
        int(c): {
            "pinned": bool(pinned[c]),
            "spatial_std": float(spatial_std[c]),
            "mean": float(x[:, c].mean()),
            "counted": bool(counted[c]),
        }
        for c in range(z.shape[1])
    }
    return {
        "x_image_saturated": float(pinned[counted].mean()),
        "x_image_spatial_std": float(spatial_std[counted].mean()),
        "x_image_channels": channels,
    }


def zero_label_channels(env: DoomEnv) -> np.ndarray:
    """bool (V,): the channels whose aux labels are all zero by construction: supervised by the aux loss
    (`DoomEnv.aux_mask`) but the word of no object (`Dataset.actors`: the function words, 'go', 'the', 'what', ...),
    so that the aux loss trains them to 0 everywhere. Not a collapse (issue 61)."""
    fire = {w for actor in env.dataset.actors.values() for w in actor.words()}
    return np.array([bool(m) and w not in fire for w, m in zip(env.vocab.words, env.aux_mask, strict=True)])


def conv3_drift(model, cfg) -> dict:
    """How conv3 moved from its initial weights (the run's seeded init, rebuilt): per channel the share of its weights
    moved in the channel's majority direction (0.5: no common direction; 1: a uniform signed shift, which over the
    non-negative relu(conv2) inputs moves the whole channel at once: the No Aux collapse, issue 48) and the sum of
    its weight changes. Medians over channels."""
    from emml.models import build_model

    env = cfg.env
    with torch.random.fork_rng(devices=[]):  # the caller's generator is left as it was
        torch.manual_seed(cfg.seed)  # the trainer's seeding before it builds the model (emml/rl/trainer.py)
        init = build_model(
            cfg.model, model.image_encoder.conv3.out_channels, env.height, env.width, env.max_steps, **cfg.model_options
        )
    delta = (model.image_encoder.conv3.weight - init.image_encoder.conv3.weight).detach().flatten(1)
    moved = delta != 0
    if not moved.any():  # an untrained model: no direction to speak of
        return {"conv3_one_way": None, "conv3_shift": 0.0}
    same = (torch.sign(delta) == torch.sign(delta.mean(1, keepdim=True))) & moved
    one_way = same.sum(1) / moved.sum(1).clamp(min=1)
    return {"conv3_one_way": float(one_way.median()), "conv3_shift": float(delta.sum(1).abs().median())}


def counted_words(result: dict) -> str:
    """The words whose channels the collapse figures count (`diagnose`'s ``x_image_counted``), in words: 'all 22
    words', or 'the 14 words ... (not the 8 whose aux labels are all zero, trained to 0 by the aux loss: ...)'."""
    counted, left = result.get("x_image_counted") or [], result.get("x_image_uncounted") or []
    if not left:
        return f"all {len(counted)} words" if counted else "every channel"
    return (
        f"the {len(counted)} words whose aux labels can be 1: {', '.join(counted)} (not the {len(left)} whose aux "
        f"labels are all zero, which the aux loss trains to 0: {', '.join(left)})"
    )


def saturation_warning(result: dict) -> str | None:
    """The training log's warning when x_I has collapsed (`SATURATION_WARNING` of the channels counted: not those an
    Aux run's all-zero labels train to 0), naming the words counted and those pinned; else None."""
    frac = result.get("x_image_saturated")
    if frac is None or frac < SATURATION_WARNING:
        return None
    channels = result.get("x_image_channels") or {}
    counted = [w for w, c in channels.items() if c.get("counted", True)]
    pinned = [w for w in counted if channels[w]["pinned"]]
    how_many = (
        f"{len(pinned)} of the {len(counted)} conv3 channels counted ({frac:.0%})"
        if counted
        else (f"{frac:.0%} of the conv3 channels")
    )
    return (
        f"WARNING: {how_many} are pinned on every cell (x_I a constant code, no gradient through it; "
        f"spatial std {result['x_image_spatial_std']:.3f}){': ' + ', '.join(pinned) if pinned else ''}; counted: "
        f"{counted_words(result)}. See docs/fidelity.md, 'No Aux'"
    )


def _single(obs: dict, device) -> dict[str, torch.Tensor]:
    """One env's observation as a (1, 1, ...) model input."""
    return obs_to_torch({k: np.asarray(v)[None] for k, v in obs.items()}, device)


def _step0(model, env: DoomEnv, episodes: int, seed: int, device) -> dict:
    """Mean step-0 move distribution per target slot (Easy), from ``episodes`` resets of ``env``."""
    per_slot: dict[int, list[np.ndarray]] = {}
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        out, _ = model(_single(obs, device), model.initial_state(1, device), _starts(1, device))
        probs = torch.softmax(out.logits[0, 0], -1).cpu().numpy()
        per_slot.setdefault(env.episode.target, []).append(probs)
    means = {slot: np.mean(p, axis=0) for slot, p in sorted(per_slot.items())}
    tv = [0.5 * float(np.abs(means[a] - means[b]).sum()) for a, b in combinations(means, 2)]
    return {
        "actor_sensitivity": max(tv) if tv else float("nan"),
        "step0_moves": {int(s): [round(float(x), 3) for x in m] for s, m in means.items()},
    }


def _starts(n: int, device) -> torch.Tensor:
    return torch.ones(1, n, dtype=torch.bool, device=device)


@torch.no_grad()
def diagnose(
    model,
    env_cfg: DoomConfig,
    episodes: int = 20,
    step0_episodes: int = 100,
    seed: int = 20_000,
    device="cpu",
    max_frames: int = 2000,
) -> dict:
    """The three diagnostics on SGN train episodes of ``env_cfg``'s difficulty (see the module docstring).

    ``episodes`` sampled episodes (at most ``max_frames`` frames) give the attention and detector figures;
    ``step0_episodes`` resets give the actor's sensitivity (Easy and House, where the spawn is fixed; None in Hard)."""
    # a run restricted to some instructions is diagnosed on its SGN training ones (all of them if it has none)
    chosen = {(task, split): sents for task, split, sents in eval_settings(env_cfg)}.get(("sgn", "train"))
    cfg = dataclasses.replace(
        env_cfg, tasks="sgn", split="train", aux_labels=True, target_in_obs=True, instructions=chosen
    )
    gen = torch.Generator().manual_seed(seed)
    logits, labels, attn, target = [], [], [], []
    with playing(model, cfg) as (env,):  # eval mode; on the way out the engine ended and the mode restored
        for i in range(episodes):
            obs, _ = env.reset(seed=seed + i)
            state, start = model.acting_state(model.initial_state(1, device)), _starts(1, device)
            done = False
            while not done and len(labels) < max_frames:
                out, state = model(_single(obs, device), state, start)
                start = torch.zeros_like(start)
                logits.append(out.aux_logits[0, 0].float().cpu().numpy())
                labels.append(obs["aux"])
                target.append(obs["target"])
                if out.attention is not None:
                    attn.append(out.attention[0, 0].cpu().numpy())
                move = int(torch.multinomial(torch.softmax(out.logits[0, 0].cpu(), -1), 1, generator=gen))
                obs, _, terminated, truncated, _ = env.step(np.array([move, 0]))
                done = terminated or truncated
        aux_mask = env.aux_mask
        zero = zero_label_channels(env)
        words = env.vocab.words
        fixed = ENV_KINDS[env_cfg.difficulty].fixed_spawn and step0_episodes  # a fixed spawn: slots are comparable
        step0 = _step0(model, env, step0_episodes, seed + episodes, device) if fixed else None
    result: dict = {"frames": len(labels)}
    target_a = np.stack(target).astype(bool)
    seen = target_a.reshape(len(target_a), -1).any(1)
    if attn and seen.any():
        a = np.stack(attn)[seen].reshape(int(seen.sum()), -1)
        t = target_a[seen].reshape(len(a), -1)
        result["attention_on_target"] = float(t[np.arange(len(a)), a.argmax(1)].mean())
        result["attention_mass_on_target"] = float((a * t).sum(1).mean())
    else:
        result["attention_on_target"] = result["attention_mass_on_target"] = None
    z, y = np.stack(logits), np.stack(labels)
    p = _sigmoid(z)  # the detectors are sigmoid(conv3) whatever x_I reads (the aux task's predictions)
    per_word = {}
    for w in np.flatnonzero(aux_mask):
        ap = average_precision(p[:, w], y[:, w])
        if not np.isnan(ap):
            per_word[words[w]] = round(ap, 3)
    result["detector_ap"] = float(np.mean(list(per_word.values()))) if per_word else None
    result["detector_ap_words"] = per_word
    result.update(step0 or {"actor_sensitivity": None, "step0_moves": {}})
    # collapse only (issue 61): in a run with aux labels, the channels its all-zero labels train to 0 are not counted
    counted = ~zero if env_cfg.aux_labels else np.ones(len(words), dtype=bool)
    saturation = x_image_saturation(z, model.cfg.x_image, counted)
    saturation["x_image_channels"] = {words[c]: v for c, v in saturation["x_image_channels"].items()}
    saturation["x_image_counted"] = [w for w, c in zip(words, counted, strict=True) if c]
    saturation["x_image_uncounted"] = [w for w, c in zip(words, counted, strict=True) if not c]
    result.update(saturation)
    return result


SCALARS = (
    "attention_on_target",
    "attention_mass_on_target",
    "detector_ap",
    "actor_sensitivity",
    "x_image_saturated",
    "x_image_spatial_std",
)
"""The figures logged to MLflow (as diag/<name>) and printed at each evaluation."""


def summary_line(result: dict) -> str:
    """One line of the scalar figures, for logs."""
    parts = []
    for k in SCALARS:
        v = result.get(k)
        digits = 3 if k == "x_image_spatial_std" else 2  # a collapsed map's spread is below 0.01
        parts.append(f"{k} {'n/a' if v is None else f'{v:.{digits}f}'}")
    return "diagnose: " + ", ".join(parts)


def diagnose_checkpoint(
    path,
    episodes: int = 20,
    step0_episodes: int = 100,
    seed: int = 20_000,
    eqa_episodes: int = 0,
    control: str | None = None,
) -> dict:
    """Rebuild a checkpoint's model (its own config and vocabulary, ``control`` as in `emml.runs.rundir.load_model`)
    and diagnose it: the SGN figures above (none when ``episodes`` is 0) and, with ``eqa_episodes``, the EQA
    per-question ones under "eqa" (emml/eval/diagnose_eqa.py)."""
    from emml.eval.diagnose_eqa import diagnose_eqa
    from emml.runs.rundir import load_model

    model, cfg = load_model(path, control=control)
    result = diagnose(model, cfg.env, episodes, step0_episodes, seed) if episodes else {}
    result.update(conv3_drift(model, cfg))
    if eqa_episodes:
        result["eqa"] = diagnose_eqa(model, cfg.env, eqa_episodes, seed)
    result["control"] = model.cfg.control
    return result
