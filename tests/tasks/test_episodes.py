import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from emml.tasks.episodes import N_OBJECTS, sample_episode
from emml.tasks.language import answer, load_dataset, referents

DS = load_dataset("doom")
SENTENCES = list(DS.sentences)


@settings(max_examples=400, deadline=None)
@given(index=st.integers(0, len(SENTENCES) - 1), seed=st.integers(0, 2**32 - 1))
def test_every_sampled_episode_has_exactly_one_referent(index, seed):
    sentence = SENTENCES[index]
    ep = sample_episode(sentence, DS, np.random.default_rng(seed))
    assert len(ep.scene) == N_OBJECTS == len(set(ep.scene))
    assert referents(sentence, ep.scene, DS) == [ep.target]
    if sentence.kind == "eqa":
        assert ep.answer == answer(sentence, ep.scene, DS)
        assert ep.answer in DS.answer_words()
    else:
        assert ep.answer is None


def test_target_slot_is_uniform():
    rng = np.random.default_rng(0)
    slots = [sample_episode(SENTENCES[0], DS, rng).target for _ in range(2000)]
    counts = np.bincount(slots, minlength=N_OBJECTS)
    assert counts.min() > 330 and counts.max() < 470  # 400 expected each
