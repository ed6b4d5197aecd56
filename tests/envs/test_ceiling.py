"""The blind ceiling enumerated from the episode generator (emml/envs/ceiling.py, issue 81 item 1), against values
worked by hand from the actors of emml/tasks/doom.toml (Table 7) and the House's slots (emml/envs/house_wad.py)."""

import itertools
import shutil
from fractions import Fraction as F
from pathlib import Path

import pytest

from emml.envs import ceiling
from emml.envs.ceiling import (
    ceiling_table,
    enumerate_draws,
    question_ceiling,
    sentence_ceilings,
    split_ceiling,
)
from emml.tasks.episodes import sample_episode
from emml.tasks.language import load_dataset

EASY_TEST_EQA = {
    # the torches: red, green, blue, each a short and a tall one: the colour is 1/3 whichever is asked
    "what color is the torch": ("blue", F(1, 3)),
    "what color is the short torch": ("blue", F(1, 3)),
    "what color is the tall torch": ("blue", F(1, 3)),
    # blue: a short and a tall torch, a keycard, a skullkey (no blue pillar, no blue armor): torch 2 of 4
    "which object is blue in color": ("torch", F(1, 2)),
    # size words describe torches and pillars only, and no pillar is blue: the torch, always
    "which short object is blue in color": ("torch", F(1)),
    "which tall object is blue in color": ("torch", F(1)),
    # every blue actor has 14 non-blue ones to stand beside: all 4 can be the referent, torch 2 of 4
    "which is the largest blue object": ("torch", F(1, 2)),
    "which is the smallest blue object": ("torch", F(1, 2)),
}
"""The 8 test questions of Easy: best fixed answer and its probability (ties: the first answer in sorted order)."""

EASY_TRAIN_EQA = {
    "what color is the pillar": F(1, 2),  # red, red, green, green
    "what color is the keycard": F(1, 3),  # yellow, blue, red
    "what color is the skullkey": F(1, 3),
    "what color is the armor": F(1, 2),  # green, red ('BlueArmor' renders red)
    "what color is the short pillar": F(1, 2),
    "what color is the tall pillar": F(1, 2),
    "which object is red in color": F(2, 7),  # 2 torches, 2 pillars, keycard, skullkey, armor
    "which object is yellow in color": F(1, 2),  # keycard, skullkey
    "which object is green in color": F(2, 5),  # 2 torches, 2 pillars, armor
    "which short object is red in color": F(1, 2),  # the short torch or pillar
    "which tall object is red in color": F(1, 2),
    "which short object is green in color": F(1, 2),
    "which tall object is green in color": F(1, 2),
    # largest: a referent needs 4 actors smaller by > 100 px: 4 pillars, 6 torches, 2 armors (no key): torch 6 of 12
    "which is the largest object": F(1, 2),
    # smallest: 3 skullkeys, 3 keycards, 2 armors, 6 torches (no pillar has 4 actors larger by > 100): torch 6 of 14
    "which is the smallest object": F(3, 7),
    "which is the largest red object": F(2, 7),  # 11 non-red actors: every red one can be the referent
    "which is the largest yellow object": F(1, 2),
    "which is the largest green object": F(2, 5),
    "which is the smallest red object": F(2, 7),
    "which is the smallest yellow object": F(1, 2),
    "which is the smallest green object": F(2, 5),
}
"""The 21 training questions of Easy: their best fixed answer's probability, from the actors' words and areas."""


def test_easy_eqa_test_questions_each_their_best_fixed_answer():
    got = {s.text: (s.best, s.probability) for s in sentence_ceilings("easy", "eqa", "test")}
    assert got == EASY_TEST_EQA


def test_easy_eqa_test_ceiling_is_the_mean_over_its_questions():
    """(3 × 1/3 + 2 × 1 + 3 × 1/2) / 8 = 0.5625: what the issue's reviewer measured."""
    assert split_ceiling("easy", "eqa", "test") == pytest.approx(0.5625, abs=1e-12)


def test_easy_eqa_train_questions_and_their_ceiling():
    """(12 × 1/2 + 2 × 1/3 + 3 × 2/7 + 3 × 2/5 + 3/7) / 21 = 0.43583."""
    got = {s.text: s.probability for s in sentence_ceilings("easy", "eqa", "train")}
    assert got == EASY_TRAIN_EQA
    assert split_ceiling("easy", "eqa", "train") == pytest.approx(0.43583, abs=1e-5)


def test_hard_plays_the_same_generator_so_its_eqa_ceiling_is_easys():
    """Hard draws the scene with the same `sample_episode` (only the points differ): not a uniform 1/3."""
    assert split_ceiling("hard", "eqa", "test") == pytest.approx(0.5625, abs=1e-12)
    assert split_ceiling("hard", "eqa", "train") == pytest.approx(0.43583, abs=1e-5)


@pytest.mark.parametrize("difficulty", ["easy", "hard"])
@pytest.mark.parametrize("split", ["train", "test"])
def test_doom_sgn_the_goals_slot_is_one_of_five_for_every_instruction(difficulty, split):
    rows = sentence_ceilings(difficulty, "sgn", split)
    assert len(rows) == {"train": 42, "test": 28}[split]
    for s in rows:
        assert dict(s.outcomes) == {f"slot {i}": F(1, 5) for i in range(5)}, s.text
    assert split_ceiling(difficulty, "sgn", split) == pytest.approx(0.2, abs=1e-12)


def test_every_sentences_outcomes_sum_to_one_and_its_best_is_the_most_likely():
    for task, split in itertools.product(("sgn", "eqa"), ("train", "test")):
        for s in sentence_ceilings("easy", task, split):
            assert sum(p for _, p in s.outcomes) == 1, s.text
            assert s.probability == max(p for _, p in s.outcomes) and s.outcomes[0] == (s.best, s.probability)


class AllSubsets(ceiling._Branches):
    """The stand-in generator with every distractor subset a branch of its own (the real one draws one)."""

    def choice(self, pool, size, replace=False):
        subsets = list(itertools.combinations(pool, int(size)))
        return list(subsets[self._next(len(subsets))])


@pytest.mark.parametrize(
    "text", ["what color is the torch", "which is the largest yellow object", "go to the short red pillar"]
)
def test_the_answer_and_the_goals_slot_do_not_depend_on_which_distractors_are_drawn(text):
    """Every subset of the referent's pool enumerated: the same distribution of replies as one subset."""
    ds = load_dataset("doom")
    sentence = ds.find(text)

    def replies(rng):
        dist = {}
        for p, e in enumerate_draws(lambda r: sample_episode(sentence, ds, r), rng):
            reply = e.answer if sentence.kind == "eqa" else e.target
            dist[reply] = dist.get(reply, 0) + p
        return dist

    full = replies(AllSubsets)
    assert sum(full.values()) == 1 and full == replies(ceiling._Branches)


def test_enumerating_draws_walks_every_path_once_with_its_probability():
    """Two draws, the second's arity set by the first: a ∈ {0, 1, 2}, b ∈ range(a + 1); a path is rejected when
    a + b == 3 (a = 2, b = 1): probabilities 1/3, 1/6, 1/6, 1/9, 1/9 (left), 1/9."""

    def play(rng):
        a = rng.integers(3)
        b = rng.integers(a + 1)
        return None if a + b == 3 else (a, b)

    got = {v: p for p, v in enumerate_draws(play)}
    assert got == {(0, 0): F(1, 3), (1, 0): F(1, 6), (1, 1): F(1, 6), (2, 0): F(1, 9), (2, 2): F(1, 9)}


# --- the House: fixed slots (0 refrigerator, 1 office chair, 2 fish tank, 3 fireplace, 4 and 5 sofas, 6 bed) ------


def test_house_sgn_walks_to_the_named_class_slot():
    """One piece per class but the sofas: a named class is its slot, always; 'the <color> sofa' is one of two;
    'the <color> object' is the one piece of that colour, any of the 7 slots alike (7 × 3^6 colourings)."""
    test = {s.text: (s.best, s.probability) for s in sentence_ceilings("house", "sgn", "test")}
    assert test["go to the bed"] == test["go to the red bed"] == ("slot 6", 1)
    assert test["go to the red refrigerator"] == ("slot 0", 1)
    assert test["go to the red sofa"] == ("slot 4", F(1, 2))
    assert test["go to the red object"] == ("slot 0", F(1, 7))
    assert split_ceiling("house", "sgn", "test") == pytest.approx((9 + F(1, 2) + F(1, 7)) / 11, abs=1e-12)
    # train: 4 classes alone (1), 12 '<color> <class>' but sofa (1), 3 '<color> sofa' (1/2), 3 '<color> object'
    assert split_ceiling("house", "sgn", "train") == pytest.approx((16 + F(3, 2) + F(3, 7)) / 22, abs=1e-12)


def test_house_eqa_colour_questions_are_one_in_four_and_the_object_questions_favour_the_sofas():
    """'what color is the sofa': both sofas alike, in one of 4 colours: 1/4. 'what object is blue in color': one
    blue piece (7 × 3^6 = 5103 colourings, sofa in 2 × 729) or both sofas and nothing else blue (3^5 = 243): sofa
    (1458 + 243) / 5346 = 7/22."""
    test = {s.text: (s.best, s.probability) for s in sentence_ceilings("house", "eqa", "test")}
    assert test == {"what color is the sofa": ("blue", F(1, 4)), "what object is blue in color": ("sofa", F(7, 22))}
    assert split_ceiling("house", "eqa", "test") == pytest.approx((F(1, 4) + F(7, 22)) / 2, abs=1e-12)
    assert split_ceiling("house", "eqa", "train") == pytest.approx((5 * F(1, 4) + 3 * F(7, 22)) / 8, abs=1e-12)


# --- the accessors ------------------------------------------------------------------------------------------------


def test_a_question_ceiling_reads_its_own_row():
    assert question_ceiling("easy", "test", "Which short object is blue in color?") == 1.0
    assert question_ceiling("easy", "test", "what color is the torch") == pytest.approx(1 / 3)
    assert question_ceiling("hard", "train", "what color is the armor") == 0.5
    assert question_ceiling("house", "test", "what object is blue in color") == pytest.approx(7 / 22)


def test_a_question_of_another_split_or_task_or_an_unknown_difficulty_is_named():
    with pytest.raises(ValueError, match=r"question='what color is the pillar' is not an EQA test question of 'easy'"):
        question_ceiling("easy", "test", "what color is the pillar")  # a training question
    with pytest.raises(ValueError, match="allowed: .*'what color is the torch'"):
        question_ceiling("easy", "test", "go to the red torch")  # an instruction
    with pytest.raises(ValueError, match="difficulty"):
        question_ceiling("medium", "test", "what color is the torch")
    with pytest.raises(ValueError, match="split"):
        split_ceiling("easy", "eqa", "val")
    with pytest.raises(ValueError, match="task"):
        split_ceiling("easy", "vqa", "test")


def test_the_table_has_one_row_per_sentence_weighted_as_the_env_draws_them():
    table = ceiling_table("easy", "eqa", "test")
    assert list(table.columns) == ["text", "template", "best", "probability", "weight"]
    assert len(table) == 8 and table["weight"].tolist() == [1 / 8] * 8
    assert (table["probability"] * table["weight"]).sum() == pytest.approx(split_ceiling("easy", "eqa", "test"))
    assert sentence_ceilings("easy", "eqa", "test") is sentence_ceilings("easy", "eqa", "test")  # cached


def test_a_kept_enumeration_reads_back_exactly_and_a_damaged_file_is_enumerated_again(tmp_path):
    """The cache (`_cached`): what is read back is what was enumerated, Fraction for Fraction; a file that does not
    parse, or parses to rows of another shape, is enumerated again and rewritten, not raised and not trusted."""
    path = tmp_path / "easy-eqa-test.json"
    fresh = ceiling._enumerate("easy", "eqa", "test")
    calls = []

    def compute():
        calls.append(1)
        return fresh

    assert ceiling._cached(path, compute) == fresh and len(calls) == 1
    assert ceiling._cached(path, compute) == fresh and len(calls) == 1  # read, not enumerated
    kept = ceiling._cached(path, lambda: pytest.fail("read, not enumerated"))
    assert {s.text: (s.best, s.probability) for s in kept} == EASY_TEST_EQA
    for damage in ("{not json", '[{"text": "x"}]', "[]", '{"text": 1}', ""):
        path.write_text(damage)
        assert ceiling._cached(path, compute) == fresh
    assert len(calls) == 6
    assert ceiling._cached(path, compute) == fresh and len(calls) == 6  # rewritten whole


def test_the_cache_key_follows_every_input_and_each_split(monkeypatch):
    """A split is kept under its own name and under a digest of the enumeration's inputs: a changed generator or
    dataset (another digest) is never read from the file of the old one."""
    a, b = ceiling.cache_path("easy", "eqa", "test"), ceiling.cache_path("easy", "eqa", "train")
    assert a != b and ceiling.cache_path("hard", "eqa", "test") != a
    monkeypatch.setattr(ceiling, "inputs_digest", lambda: "0" * 64)
    assert ceiling.cache_path("easy", "eqa", "test") != a


def test_the_digest_reads_the_generator_and_the_datasets(tmp_path, monkeypatch):
    """`inputs_digest` over a copy of the package: editing a dataset or the generator changes it."""
    home = tmp_path / "emml"
    for folder in ceiling.INPUTS:
        shutil.copytree(Path(ceiling.__file__).resolve().parents[1] / folder, home / folder)
    fake = home / "envs" / "ceiling.py"

    def digest():
        monkeypatch.setattr(ceiling, "__file__", str(fake))
        ceiling.inputs_digest.cache_clear()
        return ceiling.inputs_digest()

    try:
        before = digest()
        assert digest() == before
        (home / "tasks" / "doom.toml").write_text((home / "tasks" / "doom.toml").read_text() + "\n# edited\n")
        after_dataset = digest()
        (home / "tasks" / "episodes.py").write_text((home / "tasks" / "episodes.py").read_text() + "\n# edited\n")
        assert len({before, after_dataset, digest()}) == 3
    finally:
        monkeypatch.undo()
        ceiling.inputs_digest.cache_clear()
