"""The language side of the tasks as data: datasets, vocabulary, tokens, and what a sentence means in a scene.

Datasets are read from ``<name>.toml`` beside this file (Doom: Table 7 of Chaplot et al., 2019; House: Table 8).
A sentence's meaning is a `Description` (object type, colour, size, superlative); `satisfies` and `answer` evaluate
it on a scene, a tuple of actor names. Nothing here assumes one global vocabulary: a `Vocabulary` is a value that a
run's config carries and its checkpoints save.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import tomllib

from emml.config.env import SPLITS as SPLITS  # the splits' one list, as the tasks' (the config's)
from emml.config.env import TASKS as TASKS  # the tasks' one list (the config declares what a run plays)
from emml.config.schema import VOCABULARY_SOURCES, check_choice  # the config's allowed values (also imported from here)


@dataclass(frozen=True)
class Sentence:
    """One instruction (SGN) or question (EQA) of a dataset."""

    text: str
    kind: str
    """'sgn' or 'eqa'."""
    split: str
    """'train' or 'test'."""
    template: str
    """The Table 7 row it comes from, e.g. 'go to the <color> <object>'."""
    answer_attribute: str | None = None
    """EQA only: which attribute of the referent answers ('color' or 'object')."""


@dataclass(frozen=True)
class ActorWords:
    """The words that describe one actor, and its size measure."""

    object: str
    color: str
    size: str | None
    area: int
    """Sprite pixel area, compared by 'smallest'/'largest'."""

    def words(self) -> tuple[str, ...]:
        return tuple(w for w in (self.object, self.color, self.size) if w)


@dataclass(frozen=True)
class Dataset:
    name: str
    sentences: tuple[Sentence, ...]
    actors: dict[str, ActorWords]
    word_groups: dict[str, tuple[str, ...]]
    """'objects', 'colors', 'sizes', 'superlatives'."""
    superlative_margin: int

    def select(self, kind: str, split: str) -> tuple[Sentence, ...]:
        check_choice("kind", kind, TASKS)
        check_choice("split", split, SPLITS)
        return tuple(s for s in self.sentences if s.kind == kind and s.split == split)

    def find(self, text: str) -> Sentence:
        for s in self.sentences:
            if s.text == normalize(text):
                return s
        raise ValueError(f"instruction/question {text!r} is not in the {self.name} dataset")

    def content_words(self) -> frozenset[str]:
        """The words that fill a sentence's slots (every word group: objects, colours, sizes, superlatives); the
        others are the templates' function words ('go', 'to', 'the', 'what', 'which', 'is', 'color', ...)."""
        return frozenset(w for group in self.word_groups.values() for w in group)

    def answer_words(self) -> tuple[str, ...]:
        """Every word that can answer a question: the values of the attributes questions ask for."""
        attrs = {s.answer_attribute for s in self.sentences if s.kind == "eqa"}
        group = {"color": "colors", "object": "objects", "size": "sizes"}
        return tuple(w for a in sorted(attrs) for w in self.word_groups[group[a]])


def normalize(text: str) -> str:
    return " ".join(text.lower().replace("?", " ").replace(".", " ").split())


@functools.cache
def load_dataset(name: str = "doom") -> Dataset:
    """Read ``emml/tasks/<name>.toml``: sentence templates expanded, actors with their words and areas."""
    path = Path(__file__).with_name(f"{name}.toml")
    if not path.exists():
        known = sorted(p.stem for p in Path(__file__).parent.glob("*.toml"))
        raise ValueError(f"dataset={name!r} is unknown; choose one of {known}")
    raw = tomllib.loads(path.read_text())
    groups = {k: tuple(v) for k, v in raw["words"].items()}
    slot_group = {"<object>": "objects", "<color>": "colors", "<size>": "sizes", "<superlative>": "superlatives"}
    sentences = []
    for kind, key in (("sgn", "instructions"), ("eqa", "questions")):
        for row in raw[key]:
            slots = [w for w in row["template"].split() if w.startswith("<")]
            for split in SPLITS:
                for fill in row[split]:
                    words = fill.split()
                    if len(words) != len(slots):
                        raise ValueError(f"{path.name}: {fill!r} does not fill {row['template']!r}")
                    for slot, word in zip(slots, words):
                        if word not in groups[slot_group[slot]]:
                            raise ValueError(f"{path.name}: {word!r} is not one of the {slot} words")
                    it = iter(words)
                    text = " ".join(next(it) if w.startswith("<") else w for w in row["template"].split())
                    sentences.append(Sentence(text, kind, split, row["template"], row.get("answer")))
    actors_raw = dict(raw["actors"])
    margin = actors_raw.pop("superlative_margin")
    # areas are data of the dataset (tests/envs/test_sprite_areas.py measures them again from the sprites)
    actors = {n: ActorWords(a["object"], a["color"], a.get("size"), a["area"]) for n, a in actors_raw.items()}
    return Dataset(name, tuple(sentences), actors, groups, margin)


# --- vocabulary and tokens ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Vocabulary:
    """Words ↔ ids. Word ``i`` has channel ``i`` in the model (V = len(words)) and token id ``i + 1``; 0 pads."""

    words: tuple[str, ...]

    @classmethod
    def from_dataset(cls, dataset: Dataset, source: str = "all") -> Vocabulary:
        """'all': every word of every instruction, question and answer (the default: test words included, as the
        single-task ablation supervises them through aux labels); 'train_instructions': the training
        instructions' words only (the transfer experiment, Table 4, appends new words later)."""
        check_choice("vocabulary", source, VOCABULARY_SOURCES)
        if source == "all":
            texts = [s.text for s in dataset.sentences] + list(dataset.answer_words())
        else:
            texts = [s.text for s in dataset.select("sgn", "train")]
        seen: dict[str, None] = {}
        for t in texts:
            for w in t.split():
                seen.setdefault(w, None)
        return cls(tuple(seen))

    def extend(self, words) -> Vocabulary:
        """A new vocabulary with ``words`` appended (existing ids unchanged)."""
        return Vocabulary(self.words + tuple(w for w in dict.fromkeys(words) if w not in self.words))

    def __len__(self) -> int:
        return len(self.words)

    def index(self, word: str) -> int:
        try:
            return self.words.index(word)
        except ValueError:
            raise ValueError(f"word {word!r} is not in the vocabulary ({len(self)} words)") from None

    def encode(self, text: str, max_words: int) -> list[int]:
        """Token ids of ``text``, padded with 0 to ``max_words``."""
        ids = [self.index(w) + 1 for w in normalize(text).split()]
        if len(ids) > max_words:
            raise ValueError(f"max_words={max_words} is too small for {text!r} ({len(ids)} words)")
        return ids + [0] * (max_words - len(ids))


def resolve_vocabulary(spec, dataset: Dataset) -> Vocabulary:
    """A run's vocabulary from its config: None (every word of the dataset), a source name of
    `VOCABULARY_SOURCES`, or the word list itself (channel order)."""
    if spec is None:
        return Vocabulary.from_dataset(dataset)
    if isinstance(spec, str):
        check_choice("vocabulary", spec, VOCABULARY_SOURCES)
        return Vocabulary.from_dataset(dataset, spec)
    return Vocabulary(tuple(spec))


# --- meaning --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Description:
    """What a sentence says about its referent."""

    object: str | None = None
    color: str | None = None
    size: str | None = None
    superlative: str | None = None

    def matches(self, actor: ActorWords) -> bool:
        """The non-superlative part: every attribute named is the actor's."""
        return all(
            want is None or want == have
            for want, have in ((self.object, actor.object), (self.color, actor.color), (self.size, actor.size))
        )


def describe(sentence: Sentence | str, dataset: Dataset) -> Description:
    """Parse a sentence into its Description. For EQA the answered attribute's slot is not part of it: in
    'what color is the torch' the referent is 'the torch'; in 'which object is red in color' it is 'the red one'."""
    text = sentence.text if isinstance(sentence, Sentence) else normalize(sentence)
    found: dict[str, str] = {}
    for w in text.split():
        for key, group in (
            ("object", "objects"),
            ("color", "colors"),
            ("size", "sizes"),
            ("superlative", "superlatives"),
        ):
            if w in dataset.word_groups[group]:
                found[key] = w
    return Description(**found)


def referents(sentence: Sentence | str, scene: tuple[str, ...], dataset: Dataset) -> list[int]:
    """Indices of the scene's actors that the sentence singles out.

    A superlative picks the matching actor whose area beats every other matching actor by more than the margin
    (the reference environment's rule): with no such margin, nothing satisfies it."""
    desc = describe(sentence, dataset)
    matching = [i for i, name in enumerate(scene) if desc.matches(dataset.actors[name])]
    if desc.superlative is None:
        return matching
    sign = 1 if desc.superlative == "largest" else -1
    area = {i: sign * dataset.actors[scene[i]].area for i in matching}
    margin = dataset.superlative_margin
    return [i for i in matching if all(area[i] - area[j] > margin for j in matching if j != i)]


def satisfies(sentence: Sentence | str, index: int, scene: tuple[str, ...], dataset: Dataset) -> bool:
    """Whether the scene's actor at ``index`` satisfies the instruction (superlatives need the whole scene)."""
    return index in referents(sentence, scene, dataset)


def answer(question: Sentence | str, scene: tuple[str, ...], dataset: Dataset) -> str:
    """The one correct answer word of a question in a scene; a ValueError if the scene does not define one."""
    q = question if isinstance(question, Sentence) else dataset.find(question)
    found = referents(q, scene, dataset)
    if len(found) != 1:
        raise ValueError(f"{q.text!r} has {len(found)} referents in scene {scene}; exactly one is needed")
    actor = dataset.actors[scene[found[0]]]
    return getattr(actor, q.answer_attribute)
