"""Chance from the task (emml/report/chance.py, issue 81 item 1): the blind ceiling enumerated from the episode
generator (tests/envs/test_ceiling.py works its values by hand), whatever a profile's results say; a FIXTURE of
made-up results rows shows that no run moves it."""

import pytest

from emml.config.profiles import resolve_profile
from emml.experiments.claims.evidence import Chance
from emml.report import chance as chance_module
from emml.report.chance import CeilingValues, blind_prior, chance_text, paper_prior, task_ceiling
from tests.report.test_tables import PROFILE, fake_results


def test_chance_is_the_enumerated_ceiling_per_difficulty_and_column():
    """Easy and Hard (one generator): SGN 0.2, EQA test 0.5625, train 0.4358; the House: SGN 0.877 / 0.815 (a
    named class stands at its fixed slot), EQA 0.284 / 0.276, below the uniform 1/3 and taken as it is."""
    chance = task_ceiling()
    for d in ("easy", "hard"):
        assert chance.of("sgn_test", d) == pytest.approx(0.2) and chance.of("sgn_train", d) == pytest.approx(0.2)
        assert chance.of("eqa_test", d) == pytest.approx(0.5625) and chance.of("eqa_train", d) == pytest.approx(
            0.4358, abs=1e-4
        )
    assert chance.of("sgn_test", "house") == pytest.approx(0.8766, abs=1e-4)
    assert chance.of("sgn_train", "house") == pytest.approx(0.8149, abs=1e-4)
    assert chance.of("eqa_test", "house") == pytest.approx(0.2841, abs=1e-4)  # not the uniform floor 1/3
    assert chance.of("eqa_train", "house") == pytest.approx(0.2756, abs=1e-4)
    assert chance.bar("eqa_test", "easy") == pytest.approx(0.6625)
    assert chance.of("sgn_transfer:go to the red torch", "easy") == pytest.approx(0.2)  # SGN test's, as declared
    assert all(chance.measured(c, d) for d in ("easy", "hard", "house") for c in ("sgn_test", "eqa_train"))


def test_the_page_says_what_chance_is():
    assert task_ceiling().source == (
        "the best fixed answer per question (EQA) and the best fixed object slot per instruction (SGN), enumerated "
        "from the episode generator (emml/envs/ceiling.py)"
    )
    assert chance_text(task_ceiling(), ("easy", "house")) == (
        "Easy: SGN test 0.20, EQA test 0.56, SGN train 0.20, EQA train 0.44; "
        "House: SGN test 0.88, EQA test 0.28, SGN train 0.81, EQA train 0.28"
    )


def test_no_run_moves_it_the_text_only_row_is_a_row_like_any_other(tmp_path):
    """Text only at 0.9 everywhere, or no results at all: the same ceiling; the paper's tables read it too."""
    fake_results("table2", tmp_path / "high", value=lambda spec: 0.9)
    for root in (tmp_path / "high", tmp_path / "none"):
        chance = blind_prior(resolve_profile(PROFILE), root)
        assert chance.of("eqa_test", "easy") == pytest.approx(0.5625) and chance.of("sgn_test", "hard") == 0.2
    assert paper_prior() is task_ceiling()


def test_the_ceiling_of_a_difficulty_is_computed_when_first_read(monkeypatch):
    """Reading Easy's EQA test computes that split only (the House's enumeration takes seconds)."""
    asked = []
    monkeypatch.setattr(chance_module, "split_ceiling", lambda *key: asked.append(key) or 0.5)
    values = CeilingValues()
    assert len(values) == 12 and ("house", "eqa_train") in values and ("medium", "eqa_test") not in values
    assert asked == []
    assert values[("easy", "eqa_test")] == 0.5 and asked == [("easy", "eqa", "test")]
    assert values[("hard", "sgn_train")] == 0.5 and asked[-1] == ("hard", "sgn", "train")
    with pytest.raises(KeyError):
        values[("medium", "eqa_test")]


def test_an_exact_chance_has_no_floor_a_measured_one_does():
    """`Chance.exact` (evidence.py): the House's 0.284 stands below the EQA floor 1/3; a measured 0.284 is raised."""
    exact = Chance({("house", "eqa_test"): 0.284}, "ceiling", exact=True)
    measured = Chance({("house", "eqa_test"): 0.284}, "runs")
    assert exact.of("eqa_test", "house") == pytest.approx(0.284) and measured.of("eqa_test", "house") == pytest.approx(
        1 / 3
    )
    assert exact.of("eqa_test", "easy") == pytest.approx(1 / 3)  # no value: the floor, exact or not


def test_the_chance_text_names_each_column_and_which_are_uniform():
    chance = Chance({("easy", "eqa_test"): 0.45, ("hard", "sgn_train"): 0.25})
    assert chance_text(chance, ("easy",)) == (
        "Easy: SGN test 0.20 (uniform), EQA test 0.45, SGN train 0.20 (uniform), EQA train 0.33 (uniform)"
    )
    text = chance_text(chance)
    assert text.count("; ") == 2 and text.split("; ")[1].startswith("Hard: SGN test 0.20 (uniform), EQA test 0.33")
    assert "SGN train 0.25, EQA train" in text and text.split("; ")[2].startswith("House: SGN test 0.20 (uniform)")
