"""Sampling the language side of an episode: which sentence, and which 5 actors make the scene.

SGN: exactly one actor satisfies the instruction; the other four are drawn from actors that do not (for a
superlative, actors that match its other words only if the target beats them by the margin). EQA: the same
construction around the question's referent, so the question has exactly one referent and so one answer word.
The referent's place in the scene is uniform (the env puts scene[i] at slot i). The House domain keeps its furniture
at fixed slots and draws only their colours (`sample_colours`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from emml.tasks.language import Dataset, Sentence, answer, describe, referents

N_OBJECTS = 5
"""Objects per episode (the paper: 'a single room with 5 objects')."""


@dataclass(frozen=True)
class Episode:
    sentence: Sentence
    scene: tuple[str, ...]
    """Actor names; scene[i] goes to object slot i."""
    target: int
    """Index in ``scene`` of the referent: the goal (SGN) or the object the question is about (EQA)."""
    answer: str | None
    """EQA: the correct answer word; None for SGN."""


def sample_episode(sentence: Sentence, dataset: Dataset, rng: np.random.Generator) -> Episode:
    """A scene for ``sentence`` with a unique referent, at a uniformly random index."""
    desc = describe(sentence, dataset)
    names = sorted(dataset.actors)
    sign = {"largest": 1, "smallest": -1}.get(desc.superlative or "", 0)
    margin = dataset.superlative_margin

    def allowed(n: str, target: str) -> bool:
        if n == target:
            return False
        if not desc.matches(dataset.actors[n]):
            return True
        # a matching distractor is allowed only under a superlative that the target still wins by the margin
        return sign != 0 and sign * (dataset.actors[target].area - dataset.actors[n].area) > margin

    pools = {t: [n for n in names if allowed(n, t)] for t in names if desc.matches(dataset.actors[t])}
    candidates = [t for t, pool in pools.items() if len(pool) >= N_OBJECTS - 1]
    if not candidates:
        raise ValueError(f"no scene of {N_OBJECTS} objects gives {sentence.text!r} a unique referent")
    target = candidates[rng.integers(len(candidates))]
    pool = pools[target]
    distractors = list(rng.choice(pool, size=N_OBJECTS - 1, replace=False))
    scene = [str(d) for d in distractors]
    slot = int(rng.integers(N_OBJECTS))
    scene.insert(slot, target)
    scene_t = tuple(scene)
    found = referents(sentence, scene_t, dataset)
    assert found == [slot], (sentence.text, scene_t, found)  # the construction guarantees uniqueness
    ans = answer(sentence, scene_t, dataset) if sentence.kind == "eqa" else None
    return Episode(sentence, scene_t, slot, ans)


def sample_colours(
    sentence: Sentence, dataset: Dataset, slot_objects: tuple[str, ...], rng: np.random.Generator, tries: int = 10_000
) -> Episode:
    """House (Appendix C: 'randomize the colors of each object at the start of each episode'): the classes stand at
    fixed slots (``slot_objects[i]`` at slot i); each slot's colour is uniform over the assignments under which an
    instruction has exactly one referent and a question exactly one answer (rejection sampling).

    A question may have two referents that share the answer: 'what color is the sofa' with both sofas in one
    colour. ``target`` is then the first of them (the env shapes towards the nearer one)."""
    colors = dataset.word_groups["colors"]
    by_words = {(a.object, a.color): n for n, a in sorted(dataset.actors.items())}
    for _ in range(tries):
        picks = rng.integers(len(colors), size=len(slot_objects))
        scene = tuple(by_words[(obj, colors[k])] for obj, k in zip(slot_objects, picks))
        found = referents(sentence, scene, dataset)
        if sentence.kind == "sgn":
            if len(found) == 1:
                return Episode(sentence, scene, found[0], None)
        elif found:
            answers = {getattr(dataset.actors[scene[i]], sentence.answer_attribute) for i in found}
            if len(answers) == 1:
                return Episode(sentence, scene, found[0], answers.pop())
    raise ValueError(f"no colouring of {slot_objects} gives {sentence.text!r} a unique referent/answer")
