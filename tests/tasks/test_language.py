import pytest

from emml.tasks.language import (
    Vocabulary,
    answer,
    describe,
    load_dataset,
    referents,
    satisfies,
)

DS = load_dataset("doom")


def test_dataset_counts_match_table_7():
    assert len(DS.select("sgn", "train")) == 42
    assert len(DS.select("sgn", "test")) == 28
    assert len(DS.select("eqa", "train")) == 21
    assert len(DS.select("eqa", "test")) == 8
    assert len({s.text for s in DS.sentences}) == 99  # no duplicates


def test_split_rules():
    for s in DS.select("sgn", "test"):
        assert {"red", "pillar"} & set(s.text.split()), s.text
    for s in DS.select("sgn", "train"):
        assert not {"red", "pillar"} & set(s.text.split()), s.text
    for s in DS.select("eqa", "test"):
        assert {"blue", "torch"} & set(s.text.split()), s.text
    for s in DS.select("eqa", "train"):
        assert not {"blue", "torch"} & set(s.text.split()), s.text


def test_cross_task_transfer_words_are_seen_in_the_other_task():
    """Each test instruction's unseen word appears in a training question, and vice versa (§4 'Datasets')."""
    q_words = {w for s in DS.select("eqa", "train") for w in s.text.split()}
    i_words = {w for s in DS.select("sgn", "train") for w in s.text.split()}
    assert {"red", "pillar"} <= q_words
    assert {"blue", "torch"} <= i_words


def test_vocabulary_covers_every_word_and_answer():
    vocab = Vocabulary.from_dataset(DS)
    for s in DS.sentences:
        assert all(w in vocab.words for w in s.text.split())
    for w in DS.answer_words():
        assert w in vocab.words
    assert len(vocab) == len(set(vocab.words)) == 22


def test_vocabulary_encode_pads_and_extends():
    vocab = Vocabulary.from_dataset(DS, "train_instructions")
    assert "red" not in vocab.words and "pillar" not in vocab.words
    ids = vocab.encode("go to the torch", 6)
    assert ids[4:] == [0, 0] and all(i >= 1 for i in ids[:4])
    bigger = vocab.extend(["red", "pillar", "red"])
    assert bigger.words[: len(vocab)] == vocab.words and bigger.words[len(vocab) :] == ("red", "pillar")
    with pytest.raises(ValueError, match="red"):
        vocab.encode("go to the red torch", 10)
    with pytest.raises(ValueError, match="max_words"):
        vocab.encode("go to the torch", 3)


def test_actor_attributes():
    assert DS.actors["BlueArmor"].color == "red"  # renders red: the red armor
    assert DS.actors["TallRedColumn"].words() == ("pillar", "red", "tall")
    assert DS.actors["YellowCard"].size is None
    assert len(DS.actors) == 18


def test_describe_and_satisfies():
    assert describe("go to the short red pillar", DS).__dict__ == {
        "object": "pillar",
        "color": "red",
        "size": "short",
        "superlative": None,
    }
    scene = ("ShortRedColumn", "RedTorch", "GreenArmor", "BlueCard", "YellowSkull")
    assert satisfies("go to the red pillar", 0, scene, DS)
    assert not satisfies("go to the red pillar", 1, scene, DS)
    assert referents("go to the red object", scene, DS) == [0, 1]


def test_superlatives_need_the_margin():
    # skull keys and keycards differ by < 100 px: neither is 'smallest' among the two
    near = ("RedSkull", "RedCard", "TallGreenColumn", "GreenTorch", "ShortGreenTorch")
    assert referents("go to the smallest red object", near, DS) == []
    far = ("RedSkull", "TallRedColumn", "GreenArmor", "BlueCard", "YellowSkull")
    assert referents("go to the smallest red object", far, DS) == [0]
    assert referents("go to the largest red object", far, DS) == [1]


def test_answers():
    scene = ("ShortRedColumn", "GreenTorch", "BlueCard", "YellowSkull", "GreenArmor")
    assert answer("what color is the torch", scene, DS) == "green"
    assert answer("which object is blue in color", scene, DS) == "keycard"
    assert answer("which is the largest object", scene, DS) == "pillar"
    with pytest.raises(ValueError, match="referents"):
        answer("which object is green in color", scene, DS)


def test_unknown_dataset_and_sentence_errors():
    with pytest.raises(ValueError, match="dataset='nope'.*doom"):
        load_dataset("nope")
    with pytest.raises(ValueError, match="not in the doom dataset"):
        DS.find("go to the purple moon")
