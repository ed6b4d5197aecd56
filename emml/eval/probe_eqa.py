"""Would another question encoder transfer EQA to the test questions? (issue 34): `emml probe-eqa CHECKPOINT`.

A test question such as 'what color is the torch' is answered 'torch': the GA2 gate x_sent (Eq. 4) it gets from
the text encoder is the gate of the training sentences that end in the same word. This probe asks, offline and
without reinforcement learning, whether an encoder of x_sent trained on the training questions alone gives the test
questions the right gate, and which readout of the GRU does (`emml.config.schema.SENTENCE_READOUTS`).

* Frozen: the checkpoint's conv image encoder, x_I = sigmoid(conv3) (relu under ``x_image='relu'``), computed once
  per frame, and its Dual-Attention unit (Eq. 1-5, parameter-free).
* Data: the first frame of EQA episodes, where the agent answers in practice, ``episodes`` per question, for the
  run's training and test questions (those `emml eval` scores). Each episode has its own reset seed: the k-th
  episode, counting the training questions' episodes first and then the test questions', question by question and
  ``episodes`` per question, resets with ``seed + k`` (default seed 30,000: `emml eval` plays 10,000+ and
  `emml diagnose` 20,000+).
* Trained: only the x_sent encoder, x_sent = ReLU(Linear(readout(GRU(Embedding(tokens))))), a new
  `emml.models.encoders.TextEncoder` per (readout, encoder seed) whose embedding table is the checkpoint's, copied
  and frozen (the words keep what joint training taught them; the GRU and the Linear are learned), on Eq. 5's answer
  cross-entropy (x_Ans against the episode's answer word) over the training questions' frames: Adam, ``steps``
  minibatches of ``batch`` frames drawn with replacement. ``init`` 'checkpoint' (the default) starts the GRU and
  the Linear from the checkpoint's, so that the readouts differ in what they read and nothing else; 'fresh' draws
  them anew. Encoder seed s draws the minibatches (and, under 'fresh', the initial weights: a fresh ReLU gate can
  die early, seen as a train accuracy far below the checkpoint's).
* Scored: answer accuracy (the argmax of Eq. 5's answer logits is the answer word) on the training and the test
  questions' frames, overall and per question; and, the reference, the same for the checkpoint's own x_sent (the
  gate the fusion reads: `EmmlModel.sentence_gate`), which reproduces the failure.

Eq. 1's words (``eq1_words``): 'all', as the model reads them (x_BoW of every word of the question), or 'content',
x_BoW restricted to the dataset's content words (colours, objects, sizes, superlatives; the function words what,
which, is, the, color, object, in, go, to have all-zero aux labels, yet their channels fire on the kinds of object
that were referents of training questions: docs/fidelity.md, "Where EQA test fails"). It applies to the checkpoint's
encoder and to every retrained one alike.

The first frame only: the policy answers at its first step in most EQA episodes (mean episode length <= 1.12 on the
quick checkpoints), so the accuracy here is close to, not equal to, the greedy EQA accuracy of `emml eval`.
"""

from __future__ import annotations

import dataclasses
from contextlib import contextmanager
from typing import Literal

import torch
from torch import nn

from emml.config.checks import Positive, PositiveNumber, check
from emml.config.schema import ACTIVATIONS, EQ1_WORDS, SENTENCE_READOUTS, SPLITS, check_choice
from emml.envs.vector import make_env
from emml.eval.diagnose_eqa import gate_missing
from emml.eval.evaluate import eval_settings
from emml.models.encoders import TextEncoder
from emml.models.policy import word_mask
from emml.runs.rundir import load_model
from emml.tasks.language import load_dataset, resolve_vocabulary

SEED = 30_000
"""First reset seed of the probe's episodes (`emml eval` plays 10,000+, `emml diagnose` 20,000+)."""
EPISODES = 40
"""First frames per question."""
STEPS = 600
"""Adam steps per encoder."""
BATCH = 128
"""Frames per minibatch."""
LR = 3e-3
"""Adam's learning rate."""
SEEDS = 3
"""Encoder seeds per readout: 0, 1, ..."""
INITS = ("checkpoint", "fresh")
"""Values of ``init``: the retrained GRU and Linear start from the checkpoint's, or from a fresh draw."""
CLOSED_BELOW = 0.01
"""A gate channel below this for every question is closed: its word adds nothing to Eq. 5's logits (under ReLU it
is exactly 0 and gets no gradient: a dead channel)."""
IMAGE_BATCH = 256
"""Frames per conv forward when x_I is computed."""


@dataclasses.dataclass(frozen=True)
class ProbeOptions:
    """How the probe samples its frames and trains its encoders (`emml probe-eqa`'s options); `validate` names the
    first bad one and what it allows, before a checkpoint is loaded."""

    episodes: Positive = EPISODES
    """EQA episodes per question whose first frame is collected (the agent answers there)."""
    readouts: tuple[str, ...] = SENTENCE_READOUTS
    """x_sent readouts to retrain (`ModelConfig.sentence_readout` values), each once per seed; repeats count once."""
    seeds: Positive = SEEDS
    """Encoders trained per readout, minibatch seeds 0..seeds-1."""
    steps: Positive = STEPS
    """Adam steps per encoder."""
    batch: Positive = BATCH
    """Frames per minibatch."""
    lr: PositiveNumber = LR
    """Adam's learning rate."""
    seed: int = SEED
    """First reset seed of the collected episodes."""
    eq1_words: Literal[EQ1_WORDS] = "all"
    """Words Eq. 1 sums the channels of: one of EQ1_WORDS."""
    init: Literal[INITS] = "checkpoint"
    """Where the retrained GRU and Linear start: one of INITS."""
    activation: Literal[ACTIVATIONS] = "relu"
    """x_sent's activation on the retrained Linear (`ModelConfig.sentence_activation` values: relu, the paper's, or
    softplus)."""

    def validate(self) -> ProbeOptions:
        """These options with the readouts' repeats dropped; ValueError naming the first bad option."""
        check(self)
        readouts = tuple(dict.fromkeys(self.readouts))
        if not readouts:
            raise ValueError("readouts=() names no readout; choose from " + ", ".join(map(repr, SENTENCE_READOUTS)))
        for readout in readouts:
            check_choice("readouts", readout, SENTENCE_READOUTS)
        return dataclasses.replace(self, readouts=readouts)


def probe_questions(model, cfg) -> dict[str, tuple[str, ...]]:
    """The EQA questions per split (train, test) that the run is scored on; ValueError saying why the probe cannot
    run on this model or run: no GA2 gate (Eq. 4) to probe, x_I read from the labels, or no EQA train and test."""
    why = gate_missing(model)
    if why is not None:
        raise ValueError(f"probe-eqa retrains the GA2 gate x_sent (Eq. 4): {why}")
    if model.cfg.control == "detectors":
        raise ValueError(
            "probe-eqa reads x_I from the conv (Eq. 1); this run plays under control 'detectors' (x_I := aux labels)"
        )
    dataset = load_dataset(cfg.env.dataset)
    splits = {split: chosen for task, split, chosen in eval_settings(cfg.env) if task == "eqa"}
    if not splits:
        raise ValueError(f"the run is not scored on EQA (env.tasks={cfg.env.tasks!r}): no question to probe")
    missing = [s for s in SPLITS if s not in splits]
    if missing:
        raise ValueError(
            f"probe-eqa trains on the EQA training questions and scores the test questions; the run is not scored "
            f"on EQA {' or '.join(missing)} (its words are outside the run's vocabulary, or it is restricted to "
            "some sentences)"
        )
    return {s: splits[s] or tuple(x.text for x in dataset.select("eqa", s)) for s in SPLITS}


@contextmanager
def _eval_mode(model):
    """The model in eval mode; its mode restored on the way out."""
    was_training = model.training
    model.eval()
    try:
        yield model
    finally:
        model.train(was_training)


@torch.no_grad()
def image_features(model, images: torch.Tensor) -> torch.Tensor:
    """uint8 frames (N, 3, H, W) -> x_I (N, V, h, w): sigmoid(conv3), or relu under ``x_image='relu'``."""
    act = torch.sigmoid if model.cfg.x_image == "sigmoid" else torch.relu
    return torch.cat(
        [act(model.image_encoder(images[k : k + IMAGE_BATCH])) for k in range(0, len(images), IMAGE_BATCH)]
    )


def collect_frames(model, cfg, questions: dict[str, tuple[str, ...]], episodes: int, seed: int = SEED) -> dict:
    """Per split, the first frame of ``episodes`` EQA episodes per question (seeds as in the module docstring):
    x_I, tokens, answer word index and question index of every frame. Each split's env is closed on the way out."""
    data, k = {}, seed
    for split in SPLITS:
        chosen = questions[split] if cfg.env.instructions else None  # a run restricted to some sentences
        env_cfg = dataclasses.replace(cfg.env, tasks="eqa", split=split, aux_labels=False, instructions=chosen)
        images, tokens, answers, index = [], [], [], []
        env = make_env(env_cfg)
        try:
            for j, question in enumerate(questions[split]):
                for _ in range(episodes):
                    obs, _ = env.reset(seed=k, options={"sentence": question})
                    k += 1
                    images.append(torch.as_tensor(obs["image"]))
                    tokens.append(torch.as_tensor(obs["tokens"]))
                    answers.append(env.answer_id)
                    index.append(j)
        finally:
            env.close()
        data[split] = {
            "x_image": image_features(model, torch.stack(images)),
            "tokens": torch.stack(tokens).long(),
            "answer": torch.tensor(answers),
            "question": torch.tensor(index),
            "questions": questions[split],
        }
    return data


def eq1_mask(cfg, eq1_words: str) -> torch.Tensor | None:
    """(V,) 1 for the words Eq. 1 reads under ``eq1_words`` ('content': `Dataset.content_words`), None for 'all'."""
    if eq1_words == "all":
        return None
    dataset = load_dataset(cfg.env.dataset)
    return word_mask(resolve_vocabulary(cfg.env.vocabulary, dataset).words, dataset.content_words())


def answer_logits(model, frames: dict, x_sent: torch.Tensor) -> torch.Tensor:
    """Eq. 1-5 on the frames' x_I and x_BoW (its words masked by ``frames['eq1_mask']`` when there is one), under the
    gate ``x_sent``: the answer logits (N, V)."""
    x_bow = model.text_encoder.bag_of_words(frames["tokens"])
    if frames.get("eq1_mask") is not None:
        x_bow = x_bow * frames["eq1_mask"]
    return model.fusion(frames["x_image"], x_bow, x_sent).answer_logits


@torch.no_grad()
def accuracy(model, frames: dict, x_sent: torch.Tensor) -> tuple[float, dict[str, float]]:
    """Answer accuracy of the frames under ``x_sent``: overall, and per question."""
    ok = (answer_logits(model, frames, x_sent).argmax(1) == frames["answer"]).float()
    per_question = {q: float(ok[frames["question"] == j].mean()) for j, q in enumerate(frames["questions"])}
    return float(ok.mean()), per_question


def fresh_encoder(model, readout: str, seed: int, init: str = "checkpoint", activation: str = "relu") -> TextEncoder:
    """A new x_sent encoder of the checkpoint's sizes reading ``readout`` under ``activation``: its GRU and Linear the
    checkpoint's
    (``init='checkpoint'``) or drawn under ``seed`` ('fresh'; the global RNG is restored), its embedding table the
    checkpoint's, copied and frozen."""
    text = model.text_encoder
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        encoder = TextEncoder(
            text.vocab_size,
            text.embedding.embedding_dim,
            text.gru.hidden_size,
            sentence=True,
            readout=readout,
            activation=activation,
        )
    if init == "checkpoint":
        encoder.load_state_dict(text.state_dict())
    encoder.embedding.weight.data.copy_(text.embedding.weight.detach())
    encoder.embedding.weight.requires_grad_(False)
    return encoder


def train_encoder(
    model,
    frames: dict,
    readout: str,
    seed: int,
    steps: int = STEPS,
    batch: int = BATCH,
    lr: float = LR,
    init: str = "checkpoint",
    activation: str = "relu",
) -> TextEncoder:
    """A `fresh_encoder` trained on Eq. 5's cross-entropy over ``frames`` (the training questions'), the rest of
    the model frozen; seed ``seed`` draws its initial weights and its minibatches."""
    encoder = fresh_encoder(model, readout, seed, init, activation)
    optimizer = torch.optim.Adam([p for p in encoder.parameters() if p.requires_grad], lr=lr)
    draw = torch.Generator().manual_seed(seed)
    n = len(frames["answer"])
    for _ in range(steps):
        rows = torch.randint(n, (batch,), generator=draw)
        mini = {
            "x_image": frames["x_image"][rows],
            "tokens": frames["tokens"][rows],
            "eq1_mask": frames.get("eq1_mask"),
        }
        logits = answer_logits(model, mini, encoder(mini["tokens"])[1])
        loss = nn.functional.cross_entropy(logits, frames["answer"][rows])
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    return encoder


def _scores(model, data: dict, gate) -> dict:
    """{'train': acc, 'test': acc, 'per_question': {split: {question: acc}}, 'closed': [answer channel, ...]} under
    the gate ``gate(tokens)``; 'closed': the channels of the questions' answers whose gate is below CLOSED_BELOW for
    every question of both splits."""
    out = {"per_question": {}}
    with torch.no_grad():
        peak = None
        for split in SPLITS:
            x_sent = gate(data[split]["tokens"])
            out[split], out["per_question"][split] = accuracy(model, data[split], x_sent)
            peak = x_sent.amax(0) if peak is None else torch.maximum(peak, x_sent.amax(0))
        answers = torch.cat([data[split]["answer"] for split in SPLITS]).unique()
        out["closed"] = [int(a) for a in answers if peak[a] < CLOSED_BELOW]
    return out


def _mean(runs: list[dict], questions: dict[str, tuple[str, ...]]) -> dict:
    """The mean over encoder seeds of `_scores`, overall and per question."""
    mean = {split: sum(r[split] for r in runs) / len(runs) for split in SPLITS}
    mean["per_question"] = {
        split: {q: sum(r["per_question"][split][q] for r in runs) / len(runs) for q in questions[split]}
        for split in SPLITS
    }
    return mean


def probe_eqa(model, cfg, options: ProbeOptions = ProbeOptions()) -> dict:
    """The probe of the module docstring on ``model`` and its run's TrainConfig ``cfg``: the checkpoint encoder's
    scores, then per readout one trained encoder per seed 0..``options.seeds``-1 and their mean. ValueError (before
    any engine starts) for a bad option or a model or run the probe cannot read (`probe_questions`)."""
    o = options.validate()
    questions = probe_questions(model, cfg)
    result = {
        "model": model.cfg.name,
        "readout": model.text_encoder.readout,
        "x_image": model.cfg.x_image,
        **{k: v for k, v in dataclasses.asdict(o).items() if k not in ("readouts", "seeds")},
        "questions": {s: list(q) for s, q in questions.items()},
        "frames": {},
        "checkpoint_encoder": None,
        "readouts": {},
    }
    with _eval_mode(model):
        data = collect_frames(model, cfg, questions, o.episodes, o.seed)
        mask = eq1_mask(cfg, o.eq1_words)
        for split in SPLITS:
            data[split]["eq1_mask"] = mask
        result["frames"] = {s: len(data[s]["answer"]) for s in SPLITS}
        result["checkpoint_encoder"] = _scores(model, data, model.sentence_gate)
        for readout in o.readouts:
            runs = []
            for s in range(o.seeds):
                encoder = train_encoder(model, data["train"], readout, s, o.steps, o.batch, o.lr, o.init, o.activation)
                runs.append({"seed": s, **_scores(model, data, lambda tokens, e=encoder: e(tokens)[1])})
            result["readouts"][readout] = {"runs": runs, "mean": _mean(runs, questions)}
    return result


def probe_checkpoint(path, options: ProbeOptions = ProbeOptions()) -> dict:
    """`probe_eqa` on a checkpoint (`emml.runs.rundir.load_model`), the options checked before it is loaded; the result
    names the checkpoint."""
    options = options.validate()
    model, cfg = load_model(path)
    return {"checkpoint": str(path), **probe_eqa(model, cfg, options)}


def probe_table(result: dict) -> str:
    """The probe as text: train and test accuracy of the checkpoint's encoder and of each readout (per seed and
    mean), then per test question the checkpoint's accuracy and each readout's mean over seeds."""
    lines = [
        f"EQA question-encoder probe (issue 34) of {result.get('checkpoint', result['model'])}",
        f"first frames: {result['episodes']} per question (seeds {result['seed']:,}+; {result['frames']['train']} "
        f"train, {result['frames']['test']} test); x_sent's GRU + Linear retrained on the training questions "
        f"({result['steps']} Adam steps, batch {result['batch']}, lr {result['lr']:g}), embedding and x_I frozen; "
        f"Eq. 1 reads {'every word' if result['eq1_words'] == 'all' else 'the content words'} of the question; "
        f"GRU and Linear start from {'the checkpoint' if result['init'] == 'checkpoint' else 'a fresh draw'}; "
        f"x_sent = {result.get('activation', 'relu')}(Linear)",
        "",
        f"{'x_sent encoder':<24}  {'train':>5}  {'test':>5}  per seed (train/test, closed answer channels)",
    ]
    own = result["checkpoint_encoder"]
    lines.append(
        f"{'checkpoint (' + repr(result['readout']) + ')':<24}  {own['train']:5.2f}  {own['test']:5.2f}  "
        f"closed {len(own.get('closed', []))}"
    )
    for readout, r in result["readouts"].items():
        seeds = "  ".join(f"{x['train']:.2f}/{x['test']:.2f} ({len(x.get('closed', []))})" for x in r["runs"])
        lines.append(
            f"{'retrained ' + repr(readout):<24}  {r['mean']['train']:5.2f}  {r['mean']['test']:5.2f}  {seeds}"
        )
    tests = result["questions"]["test"]
    width = max(len(q) for q in tests)
    readouts = list(result["readouts"])
    lines += [
        "",
        f"{'test question':<{width}}  {'checkpoint':>10}  " + "  ".join(f"{repr(r) + ' mean':>11}" for r in readouts),
    ]
    for q in tests:
        means = "  ".join(f"{result['readouts'][r]['mean']['per_question']['test'][q]:11.2f}" for r in readouts)
        lines.append(f"{q:<{width}}  {own['per_question']['test'][q]:10.2f}  {means}")
    return "\n".join(lines)
