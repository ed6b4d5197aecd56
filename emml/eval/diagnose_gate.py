"""Does the question gate open the answer's attribute on a question about an unseen word (issue 82)?

Dual-Attention answers with Eq. 5 over x_GA2 = f_GA(x_SA, x_sent) (Eq. 4): x_sent (N, V) scales conv3 channel i,
the detector of vocabulary word i (the aux task's labels, §3.2, put word i's objects on channel i:
emml/envs/labels.py), so that a colour question is answered only where x_sent opens the colour channels and an
object question only where it opens the object channels. The test questions of the Doom dataset each name a word
that no training question names ('torch', 'blue': Table 7); whether the gate opens the right kind of channel on
them decided EQA test on the stated model's seeds (issue 82: seed 2 opens the colours on "what colour is the torch"
and scores 0.578; seed 0 opens the objects and scores 0.380). Two figures, logged at every evaluation beside the
other ``diag/*`` figures (`gate_metrics`, emml/rl/trainer.py) and filled for committed checkpoints (`emml diagnose
--gate`):

* ``gate_on_attribute`` — over the run's EQA test questions whose subject is unseen (`unseen_subjects`: a content
  word that no EQA training question of the run names, read from the dataset's splits), the mean of the gate's mass
  on the answer's attribute channels (the colour words' channels for a colour question, the object words' for an
  object question) as a fraction of its mass on all V channels. A question whose gate is 0 on every channel puts
  no mass on its attribute: 0. The same mean per attribute beside it (``gate_on_color``, ``gate_on_object``): the
  Doom test split has 3 colour and 5 object questions, and the object questions' gate sits at 0.99-1.00 on Table
  2's three Easy·Aux seeds, so the overall mean hides most of a colour question's failure.
* ``gate_dead`` — the answer words (`Dataset.answer_words`: the words Eq. 5 can have to answer) whose gate channel
  is exactly 0 on every EQA question of the run, train and test: a ReLU unit no gradient reaches (§3's x_sent =
  ReLU(Linear(GRU(T)))), so the word is never answered (issue 81: seed 0's 'blue').

x_sent is a function of the question's tokens only (`EmmlModel.sentence_gate`: the text encoder, or the word-type
gate under control 'type_gate'), so the figures need no engine and cost one text-encoder pass over the questions.
Only a model with a GA2 gate has them (`emml.eval.diagnose_eqa.gate_missing`); for any other, and for a run not
scored on EQA test, there is nothing to log.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from emml.config.schema import DoomConfig
from emml.eval.diagnose_eqa import gate_missing
from emml.eval.evaluate import eval_settings
from emml.tasks.language import Dataset, load_dataset, resolve_vocabulary

ATTRIBUTE_GROUP = {"color": "colors", "object": "objects", "size": "sizes"}
"""A question's answer attribute (`Sentence.answer_attribute`) → the dataset's word group that answers it."""
SCALARS = ("gate_on_attribute", "gate_on_color", "gate_on_object", "gate_on_size", "gate_dead")
"""The figures logged as diag/<name> at each evaluation (`gate_metrics`), those the run has (a dataset whose test
questions ask no size has no ``gate_on_size``)."""
ATTRIBUTE_SCALARS = tuple(f"gate_on_{a}" for a in ATTRIBUTE_GROUP)
"""The per-attribute means among `SCALARS`."""


@dataclass(frozen=True)
class GateQuestion:
    """One EQA test question whose subject no training question names."""

    text: str
    """The question, as the dataset writes it."""
    attribute: str
    """What answers it: 'color', 'object' (or 'size'): `Sentence.answer_attribute`."""
    unseen: tuple[str, ...]
    """Its content words that no EQA training question of the run names ('torch', 'blue')."""


def unseen_subjects(dataset: Dataset, train: tuple[str, ...], test: tuple[str, ...]) -> list[GateQuestion]:
    """The questions of ``test`` with a content word (`Dataset.content_words`) that none of ``train`` names, each
    with that word and its answer attribute; in ``test``'s order."""
    content = dataset.content_words()
    named = {w for q in train for w in q.split()}
    out = []
    for text in test:
        sentence = dataset.find(text)
        if sentence.kind != "eqa":
            raise ValueError(f"unseen_subjects: {text!r} is a {sentence.kind!r} sentence; allowed: 'eqa' questions")
        unseen = tuple(w for w in dict.fromkeys(text.split()) if w in content and w not in named)
        if unseen:
            out.append(GateQuestion(text, sentence.answer_attribute, unseen))
    return out


def attribute_channels(words: tuple[str, ...], dataset: Dataset, attribute: str) -> np.ndarray:
    """bool (V,): the channels of the words that answer ``attribute`` (channel i is word i of the run's
    vocabulary, the aux task's labelling)."""
    if attribute not in ATTRIBUTE_GROUP:
        raise ValueError(f"answer attribute {attribute!r} is unknown; allowed: {', '.join(ATTRIBUTE_GROUP)}")
    group = set(dataset.word_groups[ATTRIBUTE_GROUP[attribute]])
    return np.array([w in group for w in words], dtype=bool)


def attribute_fraction(gate: np.ndarray, on: np.ndarray) -> float:
    """The gate's mass on the ``on`` channels (bool (V,)) over its mass on every channel; 0 when it is 0 on every
    channel. The gate is x_sent, >= 0 under ReLU and softplus."""
    gate = np.asarray(gate, dtype=np.float64)
    if gate.shape != on.shape:
        raise ValueError(f"attribute_fraction: gate {gate.shape} and channel mask {on.shape} differ")
    if (gate < 0).any():
        raise ValueError("attribute_fraction: the gate x_sent must be >= 0 (ReLU or softplus of Eq. 4's Linear)")
    total = gate.sum()
    return float(gate[on].sum() / total) if total > 0 else 0.0


def dead_channels(gates: np.ndarray, words: tuple[str, ...], candidates: tuple[str, ...]) -> list[str]:
    """The words of ``candidates`` (in vocabulary order) whose gate channel is exactly 0 in every row of ``gates``
    (questions, V)."""
    gates = np.asarray(gates)
    if gates.ndim != 2 or gates.shape[1] != len(words):
        raise ValueError(f"dead_channels: gates must be (questions, {len(words)}), got {gates.shape}")
    zero = (gates == 0).all(axis=0)
    keep = set(candidates)
    return [w for w, z in zip(words, zero, strict=True) if z and w in keep]


def question_gates(model, questions: tuple[str, ...], words: tuple[str, ...], max_words: int, device="cpu"):
    """(questions, V) float64: x_sent as Eq. 4 reads it for each question (`EmmlModel.sentence_gate`)."""
    from emml.tasks.language import Vocabulary

    vocab = Vocabulary(words)
    tokens = torch.tensor([vocab.encode(q, max_words) for q in questions], dtype=torch.long, device=device)
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad():
            gate = model.sentence_gate(tokens)
    finally:
        model.train(was_training)
    return gate.float().cpu().numpy().astype(np.float64)


def diagnose_gate(model, env_cfg: DoomConfig, device="cpu") -> dict:
    """The figures of the module docstring for ``model`` under its run's env config (its vocabulary, dataset and
    questions), with their detail: per unseen-subject question its fraction, its unseen words and its gate on the
    content channels; the dead answer words by name. {} when the model has no GA2 gate or the run is not scored on
    EQA test (nothing to log)."""
    if gate_missing(model) is not None:
        return {}
    settings = {(task, split): chosen for task, split, chosen in eval_settings(env_cfg)}
    if ("eqa", "test") not in settings:
        return {}
    dataset = load_dataset(env_cfg.dataset)
    words = resolve_vocabulary(env_cfg.vocabulary, dataset).words
    if len(words) != model.vocab_size:
        raise ValueError(f"diagnose_gate: {len(words)} vocabulary words for a model of {model.vocab_size} channels")

    def questions(split: str) -> tuple[str, ...]:
        chosen = settings.get(("eqa", split), ())
        return chosen or tuple(s.text for s in dataset.select("eqa", split))

    train, test = questions("train"), questions("test")
    unseen = unseen_subjects(dataset, train, test)
    every = train + test
    gates = question_gates(model, every, words, env_cfg.max_words, device)
    row = {q: g for q, g in zip(every, gates, strict=True)}
    per_question = {}
    for q in unseen:
        on = attribute_channels(words, dataset, q.attribute)
        per_question[q.text] = {
            "attribute": q.attribute,
            "unseen": list(q.unseen),
            "on_attribute": attribute_fraction(row[q.text], on),
        }
    dead = dead_channels(gates, words, dataset.answer_words())
    content = dataset.content_words()
    by_attribute = {
        f"gate_on_{a}": float(np.mean([v["on_attribute"] for v in per_question.values() if v["attribute"] == a]))
        for a in dict.fromkeys(v["attribute"] for v in per_question.values())
    }
    return {
        "gate_on_attribute": float(np.mean([v["on_attribute"] for v in per_question.values()]))
        if per_question
        else None,
        **by_attribute,
        "gate_dead": len(dead),
        "gate_dead_words": dead,
        "gate_questions": per_question,
        "gate_channels": {
            q: {w: round(float(g), 3) for w, g in zip(words, row[q], strict=True) if w in content} for q in every
        },
    }


def gate_metrics(model, cfg, device="cpu") -> dict[str, float]:
    """The trainer's call at each evaluation: {'diag/gate_on_attribute': …, 'diag/gate_dead': …} for a run with
    diagnostics on (`TrainConfig.diagnose_episodes` > 0) whose model has a GA2 gate and which is scored on EQA
    test; {} otherwise (a figure that is None is left out)."""
    if not cfg.diagnose_episodes:
        return {}
    return scalars(diagnose_gate(model, cfg.env, device))


def scalars(result: dict) -> dict[str, float]:
    """The figures of a `diagnose_gate` result that a run's curve holds, as diag/<name> keys (None left out)."""
    return {f"diag/{k}": float(result[k]) for k in SCALARS if result.get(k) is not None}


def gate_table(result: dict) -> str:
    """`emml diagnose --gate`'s text: the figures, then per unseen-subject question its fraction on the answer's
    attribute and the gate's largest content channels."""
    if not result:
        return "no GA2 gate figures: the model has no GA2 gate (Eq. 4), or the run is not scored on EQA test"
    by = ", ".join(f"{k.removeprefix('gate_on_')} {result[k]:.2f}" for k in ATTRIBUTE_SCALARS if k in result)
    dead = result["gate_dead_words"]
    lines = [
        "GA2 gate (Eq. 4) on the EQA test questions whose subject no training question names: mass on the answer's "
        f"attribute {result['gate_on_attribute']:.2f} ({by}); answer channels shut on every question: "
        f"{result['gate_dead']}" + (f" ({', '.join(dead)})" if dead else "")
    ]
    width = max(len(q) for q in result["gate_questions"])
    for q, v in result["gate_questions"].items():
        top = sorted(result["gate_channels"][q].items(), key=lambda kv: -kv[1])[:4]
        lines.append(
            f"  {q:<{width}}  unseen {'/'.join(v['unseen']):<6}  on its {v['attribute']:<6} {v['on_attribute']:.2f}"
            f"  largest: {', '.join(f'{w} {g:.1f}' for w, g in top)}"
        )
    return "\n".join(lines)


def record_gate(run_dir) -> dict:
    """Append the gate figures of a finished run's final checkpoint to its metrics mirror (metrics.csv) at the
    checkpoint's frame, the run's last, through the mirror's writer (`emml.runs.mirror.append_mirror`), holding the
    run's lock; a key already there at that frame is not written again. Returns {'frames', 'figures' (the diag/*
    values), 'written' (the keys appended), 'result' (`diagnose_gate`'s)}. ValueError naming the run when its
    checkpoint is not finished (a run in flight writes its own)."""
    from pathlib import Path

    from emml.runs.checkpoint import load_checkpoint
    from emml.runs.mirror import append_mirror, read_mirror
    from emml.runs.rundir import CHECKPOINT, METRICS, load_model
    from emml.runs.runlock import hold_run

    rdir = Path(run_dir)
    rdir = rdir.parent if rdir.name == CHECKPOINT else rdir
    with hold_run(rdir):  # no training of this run meanwhile (emml/runs/runlock.py)
        ckpt = load_checkpoint(rdir / CHECKPOINT)
        if not ckpt.get("finished"):
            raise ValueError(
                f"{rdir}: its checkpoint is not finished (frame {ckpt.get('frames', 0):,}); only a finished run's "
                "metrics.csv is appended to (a run in flight logs the gate at its evaluations)"
            )
        frames = int(ckpt["frames"])
        model, cfg = load_model(rdir / CHECKPOINT)
        result = diagnose_gate(model, cfg.env)
        figures = scalars(result)
        there = {key for step, key, _ in read_mirror(rdir / METRICS) if step == frames}
        fresh = {k: v for k, v in figures.items() if k not in there}
        if fresh:
            append_mirror(rdir / METRICS, fresh, frames)
    return {"frames": frames, "figures": figures, "written": sorted(fresh), "result": result}
