"""Chance as a blind model scores it here (emml/report/chance.py, issue 60), on a FIXTURE of made-up results rows."""

import pytest

from emml.report.chance import blind_prior
from tests.report.test_tables import PROFILE, fake_results


def test_the_blind_prior_is_the_text_only_rows_mean_per_difficulty_and_column(tmp_path):
    def value(spec):  # Text only: 0.45 in Easy, 0.5 in Hard; everything else 0.9
        return (0.45 if spec.difficulty == "easy" else 0.5) if spec.model == "text_only" else 0.9

    fake_results("table2", tmp_path, value=value)
    chance = blind_prior(PROFILE, tmp_path)
    assert chance.of("eqa_test", "easy") == pytest.approx(0.45)
    assert chance.of("eqa_train", "hard") == pytest.approx(0.5)
    assert chance.of("sgn_test", "house") == pytest.approx(0.2)  # no Table 5 run: the uniform chance
    assert not chance.measured("sgn_test", "house") and chance.measured("sgn_test", "easy")
    assert "Text only runs (easy: 6 runs, hard: 6 runs)" in chance.source


def test_no_blind_run_is_the_uniform_chance(tmp_path):
    chance = blind_prior(PROFILE, tmp_path)
    assert chance.of("eqa_test", "easy") == pytest.approx(1 / 3) and chance.of("sgn_train", "hard") == 0.2
