"""Chance as a blind model scores it here (emml/report/chance.py, issue 60), on a FIXTURE of made-up results rows."""

import pandas as pd
import pytest

from emml.config.profiles import resolve_profile
from emml.experiments.claims.evidence import Chance
from emml.report.chance import blind_prior, chance_text, paper_prior
from tests.report.test_tables import PROFILE, fake_results


def test_the_blind_prior_is_the_text_only_rows_mean_per_difficulty_and_column(tmp_path):
    def value(spec):  # Text only: 0.45 in Easy, 0.5 in Hard; everything else 0.9
        return (0.45 if spec.difficulty == "easy" else 0.5) if spec.model == "text_only" else 0.9

    fake_results("table2", tmp_path, value=value)
    chance = blind_prior(resolve_profile(PROFILE), tmp_path)
    assert chance.of("eqa_test", "easy") == pytest.approx(0.45)
    assert chance.of("eqa_train", "hard") == pytest.approx(0.5)
    assert chance.of("sgn_test", "house") == pytest.approx(0.2)  # no Table 5 run: the uniform chance
    assert not chance.measured("sgn_test", "house") and chance.measured("sgn_test", "easy")
    assert "Text only runs (easy: 6 runs, hard: 6 runs)" in chance.source


def test_no_blind_run_is_the_uniform_chance(tmp_path):
    chance = blind_prior(resolve_profile(PROFILE), tmp_path)
    assert chance.of("eqa_test", "easy") == pytest.approx(1 / 3) and chance.of("sgn_train", "hard") == 0.2
    assert chance.source == "the mean score of this profile's Text only runs (none yet)"


def test_the_blind_prior_averages_seeds_and_aux_settings_and_counts_the_runs(tmp_path):
    """The fixture's default scores 0.1 × (seed + 1): seeds 0-2 in both aux settings average 0.2 in every column;
    with one Easy run left (seed 2, No Aux) Easy's prior is that run's 0.3."""
    fake_results("table2", tmp_path / "all")
    chance = blind_prior(resolve_profile(PROFILE), tmp_path / "all")
    assert chance.values[("hard", "eqa_train")] == pytest.approx(0.2)
    keep = "text_only-easy-noaux-s2-quick"
    drop = tuple(f"text_only-easy-{a}-s{s}-quick" for a in ("aux", "noaux") for s in (0, 1, 2))
    fake_results("table2", tmp_path / "one", drop=tuple(d for d in drop if d != keep))
    chance = blind_prior(resolve_profile(PROFILE), tmp_path / "one")
    assert chance.values[("easy", "sgn_test")] == pytest.approx(0.3)
    assert chance.source == "the mean score of this profile's Text only runs (easy: 1 run, hard: 6 runs)"


def test_the_paper_prior_is_its_text_only_rows():
    """reproduce/paper/table2.csv: Text only SGN 0.2 and EQA 0.33 in each setting; table5.csv: the House's 0.63 /
    0.33 SGN train / test, 0.22 / 0.23 EQA train / test."""
    chance = paper_prior()
    expected = {("easy", "sgn_test"): 0.2, ("easy", "eqa_test"): 0.33, ("hard", "sgn_test"): 0.2}
    expected |= {("hard", "eqa_test"): 0.33, ("house", "sgn_train"): 0.63, ("house", "sgn_test"): 0.33}
    expected |= {("house", "eqa_train"): 0.22, ("house", "eqa_test"): 0.23}
    assert chance.values == pytest.approx(expected)
    assert chance.source == "the paper's Text only rows (Tables 2 and 5)"


def test_the_chance_text_names_each_column_and_which_are_uniform():
    chance = Chance({("easy", "eqa_test"): 0.45, ("hard", "sgn_train"): 0.25})
    assert chance_text(chance, ("easy",)) == (
        "Easy: SGN test 0.20 (uniform), EQA test 0.45, SGN train 0.20 (uniform), EQA train 0.33 (uniform)"
    )
    text = chance_text(chance)
    assert text.count("; ") == 2 and text.split("; ")[1].startswith("Hard: SGN test 0.20 (uniform), EQA test 0.33")
    assert "SGN train 0.25, EQA train" in text and text.split("; ")[2].startswith("House: SGN test 0.20 (uniform)")


def test_the_house_prior_is_read_without_doom_results(tmp_path):
    """Only Table 5 (the House) has results: its Text only runs (0.1 × (seed + 1), seeds 0-2) give 0.2."""
    fake_results("table5", tmp_path)
    chance = blind_prior(resolve_profile(PROFILE), tmp_path)
    assert chance.measured("sgn_test", "house") and chance.values[("house", "eqa_test")] == pytest.approx(0.2)
    assert not chance.measured("sgn_test", "easy")


def test_a_results_file_without_a_column_leaves_that_column_uniform(tmp_path):
    """Results written before a column existed: a missing score column is uniform there, no model column (no row
    can be told blind) is uniform everywhere."""
    for root, column in ((tmp_path / "a", "eqa_train"), (tmp_path / "b", "model")):
        fake_results("table2", root)
        path = root / "table2" / f"{PROFILE}.csv"
        pd.read_csv(path).drop(columns=[column]).to_csv(path, index=False)
    chance = blind_prior(resolve_profile(PROFILE), tmp_path / "a")
    assert chance.measured("sgn_test", "easy") and not chance.measured("eqa_train", "easy")
    assert blind_prior(resolve_profile(PROFILE), tmp_path / "b").values == {}
