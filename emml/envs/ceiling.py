"""The blind ceiling: the best a model that sees no frame can score, per difficulty, task, split and sentence
(issue 81, item 1), computed exactly by enumerating the episode generator.

A blind agent reads the sentence (and the step count) and nothing of the scene, so the best it can do is one fixed
reply per sentence: the answer word most often right (EQA), or the object slot most often the goal (SGN). Its score
on a sentence is that reply's probability under the generator; on a split, the generator's weighting of those
scores over the split's sentences (the env draws the sentence uniformly in the split, emml/envs/doom.py `reset`:
the mean). Nothing is sampled and nothing is read from a run: every draw the generator makes is enumerated (an exact
rational), with the generator's own code (`sample_episode` for Doom, `sample_colours` for the House) played on a
stand-in random generator that walks each of its branches once (`_Branches`).

- Doom (Easy and Hard, emml/tasks/episodes.py `sample_episode`): the referent uniform over the actors that can be
  it, its slot uniform over the 5. The four distractors, uniform over the subsets of the referent's pool, are drawn
  once (the first four of the pool): the generator asserts that the referent is the scene's one referent, so neither
  the answer (an attribute of the referent) nor the goal's slot depends on which distractors stand beside it
  (tests/envs/test_ceiling.py enumerates every subset of some sentences to check it).
- The House (Appendix C, `sample_colours`): the furniture at fixed slots, each slot's colour drawn until the
  sentence has one referent (SGN) or one answer (EQA): the accepted scene is the first draw conditioned on being
  accepted, so every one of the 4^7 colourings is enumerated and the rejected ones are left out.

The best reply of an SGN sentence is a slot: in Easy and the House a fixed place a blind agent can walk to, in Hard
the index of the scene's object (its points are drawn apart from the sentence: still one of five).

The House's enumeration walks 4^7 colourings per sentence (~20 CPU-s for its four splits), so a split's sentences
are kept once computed in <tmp>/emml-ceiling-<key>.json (`_cached`), the key a digest of every input the
enumeration reads (the sources and datasets of emml/tasks/, emml/envs/, emml/config/: `inputs_digest`): a changed
generator, dataset or house is enumerated afresh, and every process after the first (the report commands, the test
workers) reads the file. A file that does not parse is enumerated again and rewritten.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import tempfile
from dataclasses import asdict, dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
import pandas as pd

from emml.config.env import env_config_class
from emml.config.env_kinds import ENV_KINDS, HOUSE_ID
from emml.config.schema import check_choice
from emml.envs.wad import replace_with
from emml.tasks.episodes import Episode, sample_colours, sample_episode
from emml.tasks.language import SPLITS, TASKS, Dataset, Sentence, load_dataset, normalize

SLOT = "slot {}"
"""How an SGN sentence's best reply is written: the scene index of the object to walk to."""


@dataclass(frozen=True)
class SentenceCeiling:
    """The best a model that sees no frame can score on one sentence."""

    text: str
    """The instruction or question."""
    template: str
    """Its Table 7 / Table 8 row ('what color is the <size> <object>')."""
    best: str
    """The best fixed reply: an answer word (EQA), or 'slot <i>' (SGN); ties go to the first in sorted order."""
    probability: Fraction
    """The best reply's probability under the generator: the blind ceiling of the sentence, exact."""
    outcomes: tuple[tuple[str, Fraction], ...]
    """Every reply the generator makes right, with its probability (they sum to 1), most likely first."""
    weight: Fraction
    """The probability that the env draws this sentence in its split (uniform: 1 / the split's sentences)."""


class _Branches:
    """A stand-in for `numpy.random.Generator` that plays one path of a generator's draws: the draws listed in
    ``path``, then the first outcome of every later draw, recording how many outcomes each draw had (`arity`)."""

    def __init__(self, path: tuple[int, ...]):
        self.path = path
        self.arity: list[int] = []

    @property
    def probability(self) -> Fraction:
        """The path's probability: every outcome of each draw equally likely."""
        return Fraction(1, math.prod(self.arity))

    def _next(self, n: int) -> int:
        i = len(self.arity)
        self.arity.append(n)
        return self.path[i] if i < len(self.path) else 0

    def integers(self, high, size=None):
        """`Generator.integers(high)` (one draw) or `integers(high, size=k)` (k independent draws, one branch of
        high**k outcomes)."""
        if size is None:
            return self._next(int(high))
        return _digits(int(high), int(size))[self._next(int(high) ** int(size))]

    def choice(self, pool, size, replace=False):
        """The distractors: one draw, the first ``size`` of the pool (see the module docstring for why the
        ceiling does not depend on which)."""
        if replace:
            raise ValueError("choice(replace=True) is not a draw the episode generators make")
        return list(pool[: int(size)])


@functools.cache
def _digits(high: int, k: int) -> np.ndarray:
    """int (high**k, k): row c holds the k draws that outcome c of `integers(high, size=k)` stands for."""
    return np.stack(np.unravel_index(np.arange(high**k), (high,) * k), axis=1)


def enumerate_draws(play, branches: type[_Branches] = _Branches) -> list[tuple[Fraction, object]]:
    """Every path of ``play(rng)``'s random draws, with its probability: [(p, what play returned)]. A path on which
    ``play`` returns None is left out (a rejected draw); the others' probabilities are returned as they are.
    ``branches``: the stand-in generator's class (a test's may branch on every distractor subset)."""
    out, stack = [], [()]
    while stack:
        path = stack.pop()
        rng = branches(path)
        value = play(rng)
        for i in range(len(path), len(rng.arity)):  # every later draw branches: queue its other outcomes
            stack.extend(tuple([*path, *([0] * (i - len(path))), k]) for k in range(1, rng.arity[i]))
        if value is not None:
            out.append((rng.probability, value))
    return out


def _doom(sentence: Sentence, dataset: Dataset) -> list[tuple[Fraction, Episode]]:
    return enumerate_draws(lambda rng: sample_episode(sentence, dataset, rng))


def _house(sentence: Sentence, dataset: Dataset) -> list[tuple[Fraction, Episode]]:
    from emml.envs.house_wad import HOUSE  # the fixed house: which class stands at which slot (no engine needed)

    slots = tuple(s.object for s in HOUSE.slots)

    def play(rng):
        try:
            return sample_colours(sentence, dataset, slots, rng, tries=1)
        except ValueError:
            return None  # rejected: the generator draws again; the accepted draw is this one conditioned on acceptance

    found = enumerate_draws(play)
    accepted = sum(p for p, _ in found)
    return [(p / accepted, e) for p, e in found]


def _reply(episode: Episode) -> str:
    """What a blind agent must give to succeed in the episode: the answer word (EQA) or the goal's slot (SGN)."""
    return episode.answer if episode.sentence.kind == "eqa" else SLOT.format(episode.target)


def dataset_of(difficulty: str) -> Dataset:
    """The dataset a difficulty's env plays (its config's `dataset`: Doom's Table 7, the House's Table 8)."""
    check_choice("difficulty", difficulty, tuple(ENV_KINDS))
    return load_dataset(env_config_class(difficulty)().dataset)


@functools.cache
def sentence_ceilings(difficulty: str, task: str, split: str) -> tuple[SentenceCeiling, ...]:
    """Per sentence of the split, the best a model that sees no frame can score on it (its best fixed reply and
    that reply's probability), enumerated from the episode generator of ``difficulty``'s env (or read from the
    cache of that enumeration under the same inputs: see the module docstring)."""
    check_choice("difficulty", difficulty, tuple(ENV_KINDS))
    check_choice("task", task, TASKS)
    check_choice("split", split, SPLITS)
    return _cached(cache_path(difficulty, task, split), lambda: _enumerate(difficulty, task, split))


def _enumerate(difficulty: str, task: str, split: str) -> tuple[SentenceCeiling, ...]:
    dataset = dataset_of(difficulty)
    episodes = _house if ENV_KINDS[difficulty].gym_id == HOUSE_ID else _doom
    sentences = dataset.select(task, split)
    out = []
    for sentence in sentences:
        dist: dict[str, Fraction] = {}
        for p, episode in episodes(sentence, dataset):
            dist[_reply(episode)] = dist.get(_reply(episode), Fraction(0)) + p
        ranked = tuple(sorted(dist.items(), key=lambda kv: (-kv[1], kv[0])))
        best, prob = ranked[0]
        # the env's draw (emml/envs/doom.py reset): uniform over the split's sentences of the task
        out.append(SentenceCeiling(sentence.text, sentence.template, best, prob, ranked, Fraction(1, len(sentences))))
    return tuple(out)


INPUTS = ("tasks", "envs", "config")
"""The folders of the package whose sources and datasets (.py, .toml) the enumeration reads: the generator and
its datasets (tasks), the House's slots (envs/house_wad.py), which dataset each env kind plays (config)."""


@functools.cache
def inputs_digest() -> str:
    """A digest of every file in `INPUTS`: the cache key's part that changes when the enumeration could."""
    home = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for path in sorted(p for folder in INPUTS for p in (home / folder).rglob("*") if p.suffix in (".py", ".toml")):
        digest.update(path.relative_to(home).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def cache_path(difficulty: str, task: str, split: str) -> Path:
    """Where the enumeration of one split is kept: <tmp>/emml-ceiling-<difficulty>-<task>-<split>-<digest>.json."""
    name = f"emml-ceiling-{difficulty}-{task}-{split}-{inputs_digest()[:16]}.json"
    return Path(tempfile.gettempdir()) / name


def _cached(path: Path, compute) -> tuple[SentenceCeiling, ...]:
    """The sentences kept at ``path``, else ``compute()``'d and written there atomically (a concurrent writer
    writes the same bytes; a reader never sees half a file)."""
    try:
        kept = tuple(_from_json(row) for row in json.loads(path.read_text()))
        if kept:  # a split always has sentences
            return kept
    except (OSError, ValueError, TypeError, KeyError, ZeroDivisionError):
        pass  # absent, or not a file this code wrote: enumerate it again
    out = compute()
    replace_with(path, json.dumps([_to_json(s) for s in out]).encode())
    return out


def _to_json(s: SentenceCeiling) -> dict:
    row = asdict(s)
    row["probability"], row["weight"] = str(s.probability), str(s.weight)  # exact: 'p/q'
    row["outcomes"] = [[reply, str(p)] for reply, p in s.outcomes]
    return row


def _from_json(row: dict) -> SentenceCeiling:
    return SentenceCeiling(
        text=str(row["text"]),
        template=str(row["template"]),
        best=str(row["best"]),
        probability=Fraction(row["probability"]),
        outcomes=tuple((str(reply), Fraction(p)) for reply, p in row["outcomes"]),
        weight=Fraction(row["weight"]),
    )


@functools.cache
def split_ceiling(difficulty: str, task: str, split: str) -> float:
    """The best a model that sees no frame can score on a split: its sentences' ceilings weighted as the env draws
    them (the mean: uniform in the split)."""
    return float(sum(s.weight * s.probability for s in sentence_ceilings(difficulty, task, split)))


def ceiling_table(difficulty: str, task: str, split: str) -> pd.DataFrame:
    """One row per sentence: text, template, best (the best fixed reply), probability (its ceiling), weight."""
    rows = [
        {"text": s.text, "template": s.template, "best": s.best, "probability": float(s.probability),
         "weight": float(s.weight)}
        for s in sentence_ceilings(difficulty, task, split)
    ]  # fmt: skip
    return pd.DataFrame(rows, columns=["text", "template", "best", "probability", "weight"])


def question_ceiling(difficulty: str, split: str, question: str) -> float:
    """The best a model that sees no frame can score on one EQA question of a split (the probability of its best
    fixed answer): what a per-question EQA score is held against."""
    text = normalize(question)
    for s in sentence_ceilings(difficulty, "eqa", split):
        if s.text == text:
            return float(s.probability)
    known = [s.text for s in sentence_ceilings(difficulty, "eqa", split)]
    raise ValueError(f"question={question!r} is not an EQA {split} question of {difficulty!r}; allowed: {known}")


def ceilings() -> dict[tuple[str, str], float]:
    """(difficulty, '<task>_<split>') → the split's blind ceiling, for every env kind, task and split."""
    return {
        (d, f"{task}_{split}"): split_ceiling(d, task, split) for d in ENV_KINDS for task in TASKS for split in SPLITS
    }
