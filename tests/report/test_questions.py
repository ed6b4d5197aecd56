"""EQA test per question beside its blind ceiling (emml/report/questions.py, issue 81): the grounded summary G is 0
for the best blind answer to every question and 1 for a perfect score, on the ceilings enumerated from the generator;
the table page's section shows each run's row from its own counts."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from emml.report.cells import Cell
from emml.report.questions import ceilings_of, grounded, section
from emml.runs.results import questions_path, upsert_questions, upsert_result

N = 840
"""Episodes per question: a multiple of 2, 3, 5 and 7, so that every Easy ceiling (1/2, 1/3, 2/5, 2/7, 3/7) is a whole
number of successes."""


def _policy(ceilings: pd.DataFrame, successes) -> pd.DataFrame:
    """Per-question rows (successes of N, ceiling) of a policy scoring ``successes(ceiling)`` on each question."""
    return pd.DataFrame(
        {"successes": [successes(c) for c in ceilings["ceiling"]], "episodes": N, "ceiling": ceilings["ceiling"]},
        index=ceilings.index,
    )


def test_a_blind_best_answer_policy_scores_zero_and_a_perfect_one_one_on_the_enumerated_ceilings():
    test = ceilings_of("easy", "test")
    assert math.isclose(test["ceiling"].mean(), 0.5625)  # the Easy test ceiling, from the enumeration
    blind = grounded(_policy(test, lambda c: round(c * N)))  # the best fixed answer: right with probability c
    assert blind.value == pytest.approx(0, abs=1e-12)
    train = ceilings_of("easy", "train")
    assert math.isclose(train["ceiling"].mean(), 0.4358, abs_tol=5e-5)  # the Easy train ceiling
    assert grounded(_policy(train, lambda c: round(c * N))).value == pytest.approx(0, abs=1e-12)
    perfect = grounded(_policy(test, lambda c: N))
    assert perfect.value == pytest.approx(1, abs=1e-12) and perfect.se == 0
    # the two questions whose one answer is always right ('torch': no blue pillar exists) say nothing: left out
    assert set(blind.left_out) == {"which short object is blue in color", "which tall object is blue in color"}
    assert len(blind.counted) == 6 and not set(blind.counted) & set(blind.left_out)
    # a fixed wrong answer: -c/(1-c) per question, 3 questions at c=1/3 (-1/2) and 3 at c=1/2 (-1)
    assert grounded(_policy(test, lambda c: 0)).value == pytest.approx(-0.75)


def test_the_grounded_summary_and_its_error_by_hand():
    rows = pd.DataFrame(
        {"successes": [2, 9, 5], "episodes": [4, 10, 5], "ceiling": [1 / 3, 0.5, 1.0]}, index=["a", "b", "always"]
    )
    g = grounded(rows)
    # ((0.5 - 1/3) / (2/3) + (0.9 - 0.5) / 0.5) / 2 = (0.25 + 0.8) / 2
    assert g.value == pytest.approx(0.525)
    # sqrt(0.5·0.5/4 / (2/3)² + 0.9·0.1/10 / 0.5²) / 2
    assert g.se == pytest.approx(math.sqrt(0.0625 / (4 / 9) + 0.009 / 0.25) / 2)
    assert (g.counted, g.left_out) == (("a", "b"), ("always",))
    nothing = grounded(rows.loc[["always"]])
    assert math.isnan(nothing.value) and nothing.left_out == ("always",)


def test_bad_rows_are_named():
    with pytest.raises(ValueError, match=r"missing \['ceiling'\]"):
        grounded(pd.DataFrame({"successes": [1], "episodes": [2]}, index=["q"]))
    with pytest.raises(ValueError, match="question 'q': ceiling must lie in"):
        grounded(pd.DataFrame({"successes": [1], "episodes": [2], "ceiling": [1.5]}, index=["q"]))


def _results(tmp_path, runs: dict[str, str]) -> pd.DataFrame:
    path = tmp_path / "table2" / "quick.csv"
    for seed, (name, run_id) in enumerate(runs.items()):
        row = dict(run_name=name, table="table2", model="m", difficulty="easy", aux=True, seed=seed, profile="quick")
        upsert_result(path, row | dict(frames=1, git_sha="abc1234", run_id=run_id, eval_episodes=N, eqa_test=0.5))
    from emml.runs.results import read_results

    return read_results(path)


def test_the_page_section_shows_each_run_s_own_counts_beside_the_ceilings(tmp_path):
    runs = {"perfect-run": "id-p", "blind-run": "id-b", "stale-run": "id-s"}
    results = _results(tmp_path, runs)
    csv = tmp_path / "table2" / "quick.csv"
    test, train = ceilings_of("easy", "test"), ceilings_of("easy", "train")

    def counts(successes) -> dict:
        return {
            "eqa_test": {q: {"successes": successes(c), "episodes": N} for q, c in test["ceiling"].items()},
            "eqa_train": {q: {"successes": successes(c), "episodes": N} for q, c in train["ceiling"].items()},
        }

    upsert_questions(questions_path(csv), "perfect-run", "id-p", counts(lambda c: N))
    upsert_questions(questions_path(csv), "blind-run", "id-b", counts(lambda c: round(c * N)))
    upsert_questions(questions_path(csv), "stale-run", "an-earlier-training", counts(lambda c: N))
    cells = [
        Cell("Dual-Attention", "easy", True, "eqa_test", 1, [1.0], runs=["perfect-run"]),
        Cell("Text only", "easy", True, "eqa_test", 2, [0.5, 0.5], runs=["blind-run", "stale-run"]),
        Cell("Dual-Attention", "easy", True, "sgn_test", 1, [0.2], runs=["perfect-run"]),  # not an EQA cell
    ]
    text = "\n".join(section(csv, cells, results))
    lines = text.splitlines()
    perfect = next(line for line in lines if line.startswith("| Dual-Attention · Aux"))
    blind = next(line for line in lines if line.startswith("| Text only · Aux"))
    cells_of = [c.strip() for c in perfect.split("|")[1:-1]]
    assert cells_of[1:4] == ["0", "1.000", "1.00"] and cells_of[-2:] == ["+1.00 ± 0.00", "+1.00"]
    cells_of = [c.strip() for c in blind.split("|")[1:-1]]
    assert cells_of[1] == "1" and cells_of[2] == "0.562" and cells_of[-2:] == ["+0.00 ± 0.01", "+0.00"]
    assert cells_of[3:11] == ["0.33", "0.33", "0.33", "0.50", "1.00", "1.00", "0.50", "0.50"]  # Q1..Q8: the ceilings
    assert text.count("| Text only") == 1  # the stale run's counts are of another training: not read
    assert "Not yet counted per question (`emml rescore --questions`): stale-run." in text
    assert "| Q5 | which short object is blue in color | torch" in text
    assert "Left out of G: Q5 ('which short object is blue in color'), Q6" in text
    assert section(csv, cells[2:], results) == []  # no EQA test cell: no section
