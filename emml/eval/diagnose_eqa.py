"""Where an EQA answer goes wrong, per question (issue 34): `emml diagnose CHECKPOINT --eqa-episodes N`.

Per question of each EQA split the run is scored on, ``episodes`` greedy episodes (as `emml eval` plays them) give:

* ``accuracy``, ``steps`` (mean episode length: when the policy answers) and ``answers`` — the answer words taken,
  with counts ('(no answer)': the episode timed out); and
  ``by_answer`` — accuracy per correct answer word (a word the gate never opens is never answered).
* ``attended`` — at the last step (the answering step, when it answered), the scene object whose cells hold most of
  the spatial attention x_spat (Eq. 2), by its words; ``attention_on_referent`` the fraction of episodes where that
  is the question's referent, ``attention_mass_on_referent`` the mean x_spat mass on the referent's cells. Dual-
  Attention with spatial attention only (None otherwise). The cells come from the env's privileged label buffer.
  Why it sits there: ``ga1_at_referent`` / ``ga1_at_attended`` — per word of the question's bag of words, the mean
  of sigmoid(conv3)[word] over the referent's / the attended object's cells, the terms Eq. 1-2 add up into the
  attention scores (x_I under the default x_image='sigmoid').
* ``detectors_at_referent`` — what Eq. 5 can read there: sigmoid(conv3)[word] over the referent's cells for every
  word of the answer's kind (the colours for a colour question, the objects for an object question), mean over the
  episodes it is in view; ``answer_lead`` the mean over those episodes of the correct answer's value minus its
  strongest rival's. A negative lead is a detector that takes the referent for something else: with the attention
  on the referent and the gate open on the right kind, Eq. 5 still answers the rival.
* ``gate`` — the gate of Eq. 4 per vocabulary channel: x_sent = ReLU(Linear(GRU(T))), a function of the question's
  words only (the same in every episode), or the word-type gate under control 'type_gate'
  (emml/models/type_gate.py); ``gate_summary``: its value on the question's content words, the mean over colour and
  over object channels, and the mean over episodes on the correct answer's channel (the channel that must win
  Eq. 5). None for a model without a GA2 gate.

* ``closed_answers`` — the answer words whose answer logit was exactly 0 on every frame played, in every split: a
  ReLU that no gradient reaches (the baselines' head softmax(ReLU(Linear(x_S))), appendix "Baseline details"; in
  Dual-Attention x_sent's, Eq. 4-5), so the word loses to every positive logit and is not answered again;
  ``answer_peak`` each answer word's largest logit over those frames.

``splits`` holds, per split, the mean over its questions of accuracy, steps and attention on the referent (each
question once), the last rows of the text table.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections import Counter

import numpy as np
import torch

from emml.config.schema import DoomConfig
from emml.envs.doom import MOVES
from emml.eval.evaluate import eval_settings, play, playing
from emml.tasks.language import Dataset, Vocabulary, load_dataset

NO_ANSWER = "(no answer)"
"""The answer of an episode that timed out."""
NOTHING = "(no object)"
"""What the attention sits on when no scene object is in view."""
ANSWER = MOVES.index("answer")


def actor_words(dataset: Dataset, name: str) -> str:
    """'short red torch': an actor by its words (size, colour, object)."""
    a = dataset.actors[name]
    return " ".join(w for w in (a.size, a.color, a.object) if w)


def gate_missing(model) -> str | None:
    """None when the model has a GA2 gate (Eq. 4); else why there is none."""
    if "ga2" not in getattr(model.fusion, "ablations", ()):  # a fusion declares its gates (emml/models/fusion.py)
        return f"no GA2 gate in model {model.cfg.name!r} (Dual-Attention only)"
    if not model.cfg.ga2:
        return "no GA2 gate in this model (the 'w/o GA2' ablation)"
    return None


def _counts(counter: Counter) -> dict[str, int]:
    return dict(sorted(counter.items(), key=lambda kv: (-kv[1], kv[0])))


def _summarize(question: str, split: str, records: list[dict], outcomes: list[bool], gate, words, dataset) -> dict:
    """One question's row from its episodes' last-step records."""
    n = len(records)
    answers = Counter(words[r["word"]] if r["answered"] else NO_ANSWER for r in records)
    by_answer: dict[str, list[int]] = {}
    for r, ok in zip(records, outcomes):
        by_answer.setdefault(r["answer"], [0, 0])
        by_answer[r["answer"]][0] += int(ok)
        by_answer[r["answer"]][1] += 1
    row = {
        "question": question,
        "split": split,
        "episodes": n,
        "accuracy": float(np.mean(outcomes)),
        "steps": float(np.mean([r["steps"] for r in records])),
        "answers": _counts(answers),
        "by_answer": {w: {"episodes": e, "accuracy": s / e} for w, (s, e) in sorted(by_answer.items())},
        "attended": None,
        "attention_on_referent": None,
        "attention_mass_on_referent": None,
        "ga1_at_referent": None,
        "ga1_at_attended": None,
        "detectors_at_referent": None,
        "answer_lead": None,
        "gate": None,
        "gate_summary": None,
    }
    if all("mass" in r for r in records):
        attended = Counter()
        on_ref, mass_ref, x_ref, x_att = [], [], [], []
        for r in records:
            mass = r["mass"]
            best = int(np.argmax(mass))
            attended[actor_words(dataset, r["scene"][best]) if mass[best] > 0 else NOTHING] += 1
            on_ref.append(mass[best] > 0 and best == r["target"])
            mass_ref.append(mass[r["target"]])
            x_ref.append(r["x_on"][r["target"]])
            x_att.append(r["x_on"][best] if mass[best] > 0 else np.full(len(words), np.nan))
        bow = [words.index(w) for w in dict.fromkeys(question.split()) if w in words]
        for key, xs in (("ga1_at_referent", x_ref), ("ga1_at_attended", x_att)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # a column all nan (never in view): nan
                means = np.nanmean(np.stack(xs), axis=0)
            row[key] = {words[w]: None if np.isnan(means[w]) else round(float(means[w]), 3) for w in bow}
        row["attended"] = _counts(attended)
        row.update(_detectors(records, x_ref, words, dataset))
        row["attention_on_referent"] = float(np.mean(on_ref))
        row["attention_mass_on_referent"] = float(np.mean(mass_ref))
    if gate is not None:
        groups = dataset.word_groups
        content = set(groups["colors"]) | set(groups["objects"]) | set(groups["sizes"])
        row["gate"] = {w: round(float(g), 3) for w, g in zip(words, gate)}
        row["gate_summary"] = {
            "question_words": {w: row["gate"][w] for w in question.split() if w in content and w in row["gate"]},
            "colors": float(np.mean([row["gate"][w] for w in groups["colors"] if w in row["gate"]])),
            "objects": float(np.mean([row["gate"][w] for w in groups["objects"] if w in row["gate"]])),
            "answer_channel": float(np.mean([row["gate"][r["answer"]] for r in records])),
        }
    return row


def _detectors(records: list[dict], x_ref: list[np.ndarray], words, dataset) -> dict:
    """``detectors_at_referent`` and ``answer_lead`` (module docstring) from the episodes where the referent is in
    view; None where it never is, or the answer's kind is not one of the dataset's word groups."""
    kinds = [ws for ws in dataset.word_groups.values() if records[0]["answer"] in ws]
    rows = [(r["answer"], x) for r, x in zip(records, x_ref) if not np.isnan(x).all()]
    if not kinds or not rows:
        return {}
    candidates = [w for w in kinds[0] if w in words]
    index = [words.index(w) for w in candidates]
    values = np.stack([x[index] for _, x in rows])  # (episodes in view, candidates)
    leads = [
        v[candidates.index(answer)] - np.delete(v, candidates.index(answer)).max()
        for (answer, _), v in zip(rows, values)
    ]
    return {
        "detectors_at_referent": {w: round(float(m), 3) for w, m in zip(candidates, values.mean(axis=0))},
        "answer_lead": float(np.mean(leads)),
    }


def _play(model, cfg: DoomConfig, plan, device, batch: int, peak: np.ndarray) -> tuple[list[dict], list[bool]]:
    """Play ``plan`` greedily (`emml.eval.evaluate.play`); per planned episode, its last step's record (the answering
    step when it answered) and its success. ``peak`` (V,) is raised to each answer logit's largest value seen."""
    records: dict[int, dict] = {}

    def on_step(k, env, out, i):
        np.maximum(peak, out.answer_logits[0, i].float().cpu().numpy(), out=peak)
        ep = env.episode
        rec = {
            "answered": int(out.logits[0, i].argmax()) == ANSWER,
            "word": int(out.answer_logits[0, i].argmax()),
            "scene": ep.scene,
            "target": ep.target,
            "answer": ep.answer,
            "steps": records[k]["steps"] + 1 if k in records else 1,
        }
        if out.attention is not None:  # x_spat mass on each scene object's cells (Eq. 2)
            grids = env.scene_grids().astype(bool)
            rec["mass"] = (grids * out.attention[0, i].cpu().numpy()).sum(axis=(1, 2))
            x_image = torch.sigmoid(out.aux_logits[0, i]).cpu().numpy()  # (V, h, w)
            cells = grids.reshape(len(grids), -1)
            with np.errstate(invalid="ignore"):  # an object out of view: nan
                rec["x_on"] = (x_image.reshape(len(x_image), -1) @ cells.T).T / cells.sum(1, keepdims=True)
        records[k] = rec

    with playing(model, cfg, min(batch, len(plan))) as envs:
        outcomes = play(model, envs, plan, device, on_step)
    return [records[k] for k in range(len(plan))], outcomes


@torch.no_grad()
def diagnose_eqa(
    model, env_cfg: DoomConfig, episodes: int = 10, seed: int = 20_000, device="cpu", batch: int = 8
) -> dict:
    """The per-question EQA diagnostics of the module docstring, on every EQA split the run is scored on;
    episode i of the split's question j plays with reset seed ``seed + j * episodes + i``."""
    dataset = load_dataset(env_cfg.dataset)
    settings = [(split, chosen) for task, split, chosen in eval_settings(env_cfg) if task == "eqa"]
    gate_note = gate_missing(model)
    result = {
        "episodes": episodes,
        "seed": seed,
        "control": model.cfg.control,
        "gate_note": gate_note,
        "attention_note": None,
        "questions": [],
    }
    if not settings:
        result["note"] = "the run is not scored on EQA"
        return result
    vocab = Vocabulary(tuple(env_cfg.vocabulary)) if env_cfg.vocabulary else Vocabulary.from_dataset(dataset)
    words = vocab.words
    groups = dataset.word_groups
    content = {w for g in ("colors", "objects", "sizes", "superlatives") for w in groups[g]}
    result["channels"] = [w for w in words if w in content]  # the text table's gate columns
    peak = np.full(len(words), -np.inf, dtype=np.float32)
    with playing(model, env_cfg, 0):  # eval mode for the gates read below too; restored on the way out
        for split, chosen in settings:
            questions = chosen or tuple(s.text for s in dataset.select("eqa", split))
            cfg = dataclasses.replace(
                env_cfg, tasks="eqa", split=split, aux_labels=True, target_in_obs=True, instructions=chosen
            )
            # every episode its own seed: the same seeds under every question would tie their scenes together
            plan = [(seed + k, {"sentence": questions[k // episodes]}) for k in range(len(questions) * episodes)]
            records, outcomes = _play(model, cfg, plan, device, batch, peak)
            for q_index, question in enumerate(questions):
                ks = range(q_index * episodes, (q_index + 1) * episodes)
                gate = None
                if gate_note is None:
                    tokens = torch.tensor([vocab.encode(question, env_cfg.max_words)], device=device)
                    gate = model.sentence_gate(tokens)[0].cpu().numpy()
                row = _summarize(
                    question, split, [records[k] for k in ks], [outcomes[k] for k in ks], gate, words, dataset
                )
                result["questions"].append(row)
    if result["questions"] and result["questions"][0]["attended"] is None:
        result["attention_note"] = "no spatial attention x_spat in this model: attention columns n/a"
    result["splits"] = split_means(result["questions"])
    answers = [w for w in dataset.answer_words() if w in words]
    result["answer_peak"] = {w: float(f"{peak[words.index(w)]:.3g}") for w in answers}  # 3 significant: > 0 stays
    result["closed_answers"] = [w for w in answers if peak[words.index(w)] == 0.0]
    return result


def split_means(rows: list[dict]) -> dict[str, dict]:
    """Per split, the unweighted mean over its questions of accuracy, steps and attention on the referent (None
    without spatial attention): each question counts once, however often a split's sampler draws it."""
    means = {}
    for split in dict.fromkeys(r["split"] for r in rows):
        mine = [r for r in rows if r["split"] == split]
        on_ref = [r["attention_on_referent"] for r in mine]
        means[split] = {
            "questions": len(mine),
            "accuracy": float(np.mean([r["accuracy"] for r in mine])),
            "steps": float(np.mean([r["steps"] for r in mine])),
            "attention_on_referent": None if None in on_ref else float(np.mean(on_ref)),
        }
    return means


def _top(counts: dict[str, int] | None, k: int) -> str:
    if counts is None:
        return "n/a"
    return ", ".join(f"{w} {c}" for w, c in list(counts.items())[:k])


def _num(v) -> str:
    return "n/a" if v is None else f"{v:.2f}"


def eqa_table(result: dict) -> str:
    """The per-question diagnostics as text: one row per question, then the gate over the content channels."""
    head = f"EQA per question: {result['episodes']} greedy episodes each (seeds {result['seed']:,}+), control "
    lines = [head + f"{result['control']!r}"]
    if result.get("note"):
        return "\n".join(lines + [result["note"]])
    lines += [n for n in (result["gate_note"], result["attention_note"]) if n]
    rows = result["questions"]
    width = max(len(r["question"]) for r in rows)
    lines.append(
        f"{'split':<5}  {'question':<{width}}  {'acc':>4}  {'steps':>5}  {'answers (top 3)':<32}  "
        f"{'attention on (top 2)':<42}  {'on ref':>6}  {'gate on answer':>14}"
    )
    for r in rows:
        g = r["gate_summary"]
        lines.append(
            f"{r['split']:<5}  {r['question']:<{width}}  {r['accuracy']:4.2f}  {r['steps']:5.1f}  "
            f"{_top(r['answers'], 3):<32}  {_top(r['attended'], 2):<42}  {_num(r['attention_on_referent']):>6}  "
            f"{_num(g and g['answer_channel']):>14}"
        )
    for split, m in result["splits"].items():
        lines.append(
            f"{split:<5}  {'mean over its ' + str(m['questions']) + ' questions':<{width}}  {m['accuracy']:4.2f}  "
            f"{m['steps']:5.1f}  {'':<32}  {'':<42}  {_num(m['attention_on_referent']):>6}"
        )
    closed = result.get("closed_answers")
    if closed:
        lines.append(
            f"Closed answer words (logit exactly 0 on every frame played; a ReLU no gradient reaches): "
            f"{', '.join(closed)}"
        )
    if rows[0]["ga1_at_referent"] is not None:
        lines += [
            "",
            "Eq. 1-2 terms: sigmoid(conv3)[w] of the question's words, at the referent / at the attended object:",
        ]
        for r in rows:
            ref, att = r["ga1_at_referent"], r["ga1_at_attended"]
            terms = "  ".join(f"{w} {_num(ref[w])}/{_num(att[w])}" for w in ref)
            lines.append(f"{r['question']:<{width}}  {terms}")
        lines += [
            "",
            "Detectors at the referent (what Eq. 5 reads there): sigmoid(conv3)[w] of each word of the answer's",
            "kind; lead: the correct answer's minus its strongest rival's, mean over episodes (< 0: the referent",
            "is taken for another):",
        ]
        for r in rows:
            det = r["detectors_at_referent"] or {}
            values = "  ".join(f"{w} {v:.2f}" for w, v in det.items())
            lines.append(f"{r['question']:<{width}}  lead {_num(r['answer_lead']):>5}  {values}")
    if rows[0]["gate"] is not None:
        channels = result["channels"]
        lines += ["", "GA2 gate (Eq. 4) on the object and attribute channels (every channel in --json):"]
        lines.append(f"{'question':<{width}}  " + " ".join(f"{w[:7]:>7}" for w in channels))
        for r in rows:
            lines.append(f"{r['question']:<{width}}  " + " ".join(f"{r['gate'][w]:7.2f}" for w in channels))
    return "\n".join(lines)
