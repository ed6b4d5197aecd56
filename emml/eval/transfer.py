"""Transfer to new words (§5.4 'Extension: Transfer to new words', Table 4 of Chaplot et al. 2019).

A single-task SGN Dual-Attention policy is trained with a vocabulary of the training instructions' words only (aux
labels for those words). Afterwards, with no fine-tuning, it is given detectors for new words ('red', 'pillar'):
their per-frame detections, on the conv3 grid, are appended as channels of x_I, and the words are appended to the
vocabulary in the same order, so that BoW channel V+j gates detector channel j (Eq. 1). The new words' embeddings
(for x_sent) are freshly initialised. The paper assumes the detectors; ours read the engine's label buffer
(`LabelDetector`), and anything with the same interface (a module: observation → (N, k, h, w) in [0, 1]) may
replace them, a learned detector included.

What the surgery changes, and nothing else: the text encoder's BoW width and embedding table grow by k rows; the
model gains the detector. x_sent keeps its V entries and Eq. 4-5 read the first V channels (the new words are
no answers: Table 4 is SGN only), so the policy module's inputs keep their size and, for an instruction without
the new words, every output is exactly what it was (tested).
"""

from __future__ import annotations

import copy
import dataclasses
from collections import defaultdict

import numpy as np
import torch
from torch import nn

from emml.config.schema import DoomConfig
from emml.eval.metrics import TRANSFER_METRIC
from emml.tasks.language import Vocabulary

DETECTORS = ("labels",)
"""Detector kinds `make_detector` builds: 'labels' (perfect detectors from the engine's label buffer)."""
METRIC = TRANSFER_METRIC.name
"""Results column prefix: one column ``<METRIC>:<instruction>`` per evaluated instruction (the declared transfer
metric's, emml/eval/metrics.py)."""


class LabelDetector(nn.Module):
    """Detectors as the paper assumes them: for each new word, a binary mask of the cells showing an object the
    word describes, from the engine's label buffer resized to the conv3 grid (emml/envs/labels.py, the same
    labels as the auxiliary task). Reads the env's ``aux`` observation, so the env must produce labels for the
    new words (`transfer_env_config`)."""

    reads_labels = True

    def __init__(self, channels: list[int]) -> None:
        super().__init__()
        self.register_buffer("channels", torch.as_tensor(channels, dtype=torch.long), persistent=False)

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """obs["aux"] uint8 (T, B, V+k, h, w) → detections float (T·B, k, h, w)."""
        return obs["aux"].flatten(0, 1).index_select(1, self.channels).float()


def make_detector(kind: str, vocab: Vocabulary, words) -> nn.Module:
    """A detector of kind `kind` (one of DETECTORS) for ``words``, channels indexed in the extended ``vocab``."""
    if kind not in DETECTORS:
        raise ValueError(f"detector={kind!r} is unknown; allowed: {', '.join(DETECTORS)}")
    return LabelDetector([vocab.index(w) for w in words])


def check_transferable(model, vocab: Vocabulary, words) -> tuple[str, ...]:
    """The new words, checked: a Dual-Attention model with BoW gating (GA1) and spatial attention, under the
    paper's protocol (no diagnostic control), whose vocabulary does not know them yet."""
    words = tuple(words)
    cfg = model.cfg
    ga1, spatial = getattr(cfg, "ga1", None), getattr(cfg, "spatial_attention", None)  # Dual-Attention's options
    if cfg.name != "dual_attention" or not (ga1 and spatial) or cfg.control != "none":
        raise ValueError(
            "transfer needs a Dual-Attention model with GA1 and spatial attention (the BoW gate routes a new "
            f"word to its detector channel); got model name={cfg.name!r}, ga1={ga1}, "
            f"spatial_attention={spatial}, control={cfg.control!r}"
        )
    if not words or len(set(words)) != len(words):
        raise ValueError(f"words={list(words)!r} must be distinct new words (at least one)")
    known = [w for w in words if w in vocab.words]
    if known:
        raise ValueError(
            f"words {known} are already in the model's vocabulary; transfer appends unseen words: train with "
            "env.vocabulary = 'train_instructions' (reproduce/table4.toml)"
        )
    if model.detector is not None:
        raise ValueError("the model already has appended detector channels; transfer once, from a checkpoint")
    return words


def append_words(model, vocab: Vocabulary, words, detector: nn.Module, seed: int = 0):
    """(new model, extended vocabulary): a copy of ``model`` with ``words`` appended to the vocabulary, BoW and
    word-embedding table, and ``detector``'s channels appended to x_I (§5.4). The new embedding rows are drawn
    from N(0, 1) (nn.Embedding's initialisation) with a generator seeded by ``seed``; nothing is fine-tuned."""
    words = check_transferable(model, vocab, words)
    new_vocab = vocab.extend(words)
    new = copy.deepcopy(model)
    text = new.text_encoder
    old_v, k = text.vocab_size, len(words)
    text.vocab_size = old_v + k  # BoW: token id V+1+j → channel V+j, aligned with detector channel j
    if text.sentence:
        old = text.embedding
        emb = nn.Embedding(old_v + k + 1, old.embedding_dim, padding_idx=0).to(old.weight.device)
        with torch.no_grad():
            generator = torch.Generator().manual_seed(seed)
            emb.weight[old_v + 1 :] = torch.randn(k, old.embedding_dim, generator=generator)
            emb.weight[: old_v + 1] = old.weight
        text.embedding = emb
    new.detector = detector.to(next(model.parameters()).device)
    return new, new_vocab


def transfer_env_config(env: DoomConfig, vocab: Vocabulary, words, instructions=None) -> DoomConfig:
    """The trained run's env for evaluating transfer: SGN test instructions, the extended vocabulary, and labels
    for the new words only (what `LabelDetector` reads; the model's own channels get none)."""
    return dataclasses.replace(
        env,
        tasks="sgn",
        split="test",
        vocabulary=vocab.words,
        aux_labels=True,
        aux_words=tuple(words),
        instructions=tuple(instructions) if instructions else None,
    )


@torch.no_grad()
def evaluate_instructions(
    model, env_cfg: DoomConfig, instructions, episodes: int, seed: int = 10_000, device="cpu", batch: int = 8
) -> dict[str, float]:
    """Greedy success per instruction, ``episodes`` each (instruction i plays seeds seed + i·episodes + j)."""
    from emml.envs.doom import DoomEnv
    from emml.eval.evaluate import play, playing

    instructions = list(instructions)
    plan = [
        (seed + i * episodes + j, {"sentence": text}) for i, text in enumerate(instructions) for j in range(episodes)
    ]
    cfg = dataclasses.replace(env_cfg, instructions=tuple(instructions))
    with playing(model, cfg, min(batch, len(plan)), make=DoomEnv) as envs:
        outcomes = play(model, envs, plan, device)
    per = defaultdict(list)
    for (_, options), success in zip(plan, outcomes):
        per[options["sentence"]].append(success)
    return {text: float(np.mean(per[text])) for text in instructions}


def transfer_checkpoint(
    path,
    words=("red", "pillar"),
    instructions=None,
    episodes: int = 100,
    seed: int = 10_000,
    detector: str = "labels",
    device: str = "cpu",
) -> dict[str, float]:
    """Table 4 on one checkpoint: append detectors for ``words`` and score each SGN test instruction holding a new
    word (or the given ``instructions``) over ``episodes`` greedy episodes, without fine-tuning."""
    from emml.runs.rundir import load_model
    from emml.tasks.language import load_dataset

    model, cfg = load_model(path, device)
    vocab = Vocabulary(tuple(cfg.env.vocabulary))  # the trainer pins the run's word list in its config
    check_transferable(model, vocab, words)
    extended = vocab.extend(words)
    new_model, _ = append_words(model, vocab, words, make_detector(detector, extended, words), seed=cfg.seed)
    if instructions is None:
        test = load_dataset(cfg.env.dataset).select("sgn", "test")
        instructions = [s.text for s in test if set(s.text.split()) & set(words)]
    env_cfg = transfer_env_config(cfg.env, extended, words, instructions)
    torch.manual_seed(seed)
    return evaluate_instructions(new_model, env_cfg, instructions, episodes, seed=seed, device=device)


def metric_column(instruction: str) -> str:
    """The results column of one instruction's transfer accuracy (`Metric.column` of the declared transfer metric)."""
    return TRANSFER_METRIC.column(instruction)


def record_transfer(cfg, words, instructions, detector: str = "labels", seed: int = 10_000) -> dict[str, float]:
    """After a Table 4 training run: score the transfer on ``instructions`` (cfg.eval_episodes each) and add one
    column per instruction to the run's results.json and its row of the results CSV. Idempotent: columns already
    there are not recomputed."""
    import json

    from emml.runs.rundir import CHECKPOINT, RESULTS, record_result, run_dir, save_results

    rdir = run_dir(cfg)
    payload = json.loads((rdir / RESULTS).read_text())
    metrics = payload["metrics"]
    todo = [t for t in instructions if metric_column(t) not in metrics]
    if todo:
        scores = transfer_checkpoint(
            rdir / CHECKPOINT, words, todo, cfg.eval_episodes, seed=seed, detector=detector, device=cfg.device
        )
        metrics.update({metric_column(t): v for t, v in scores.items()})
        payload.update(transfer_words=",".join(words), transfer_detector=detector)  # results CSV provenance
        save_results(rdir, payload, cfg)
    else:
        record_result(payload, cfg)  # the row again, as the trainer re-records a finished run
    return {t: metrics[metric_column(t)] for t in instructions}
