"""Issue 62's finding: EQA test under the paper's stated model, against the paper's number and the blind prior. Every
verdict worked out by hand from the threshold rule (Z = 1.645 standard errors; one seed: binomial only)."""

import pandas as pd
import pytest

from emml.experiments.claims.evidence import Chance, Score
from emml.report import eqa_test
from emml.report.eqa_test import Arm, finding, read_arms
from tests.report.test_tables import PROFILE, fake_results

BLIND = Chance({("easy", "eqa_test"): 0.45}, "Text only")
PAPER = 0.58


def arm(label, *values, episodes=100):
    return Arm(label, [Score(f"{label}-s{i}", i, v, episodes, 1_500_160, 0.8) for i, v in enumerate(values)])


def verdict(arms) -> str:
    lines = finding(arms, PAPER, BLIND, "quick")
    (bold,) = [line for line in lines if line.startswith("**")]
    return bold.split("**")[1]


def test_below_the_paper_beyond_the_error_and_no_arm_above_the_blind_prior_is_not_reproduced():
    # 0.36 on 100 episodes: se sqrt(0.36 * 0.64 / 100) = 0.048, 0.58 - 0.36 = 0.22 > 1.645 * 0.048 = 0.079
    arms = [arm("ours", 0.36), arm("steps", 0.40), arm("wrong", 0.45)]  # 0.45 is the prior itself: not above
    assert verdict(arms) == "EQA test not reproduced at the quick budget under the paper's stated model."
    lines = finding(arms, PAPER, BLIND, "quick")
    assert "| ours | 0.360 (s0) | 0.360 | 0.800 | not above |" in lines
    assert "| wrong | 0.450 (s0) | 0.450 | 0.800 | not above |" in lines


def test_an_arm_above_the_blind_prior_is_named_and_runs_its_seeds_first():
    arms = [arm("ours", 0.36), arm("steps", 0.40), arm("wrong", 0.46)]
    assert verdict(arms) == (
        "EQA test below the paper's at the quick budget under the paper's stated model; 'wrong' clears the blind "
        "prior: its seeds 1 and 2 before anything changes."
    )
    assert "| wrong | 0.460 (s0) | 0.460 | 0.800 | above |" in finding(arms, PAPER, BLIND, "quick")


def test_the_stated_model_above_the_blind_prior_is_no_arm_to_run():
    # 0.47 on 1,000 episodes: se 0.0158, 0.11 below the paper > 1.645 se = 0.026; above 0.45, but it is the model
    arms = [arm("ours", 0.47, episodes=1000), arm("steps", 0.40)]
    assert verdict(arms) == "EQA test not reproduced at the quick budget under the paper's stated model."


def test_an_arm_without_a_run_is_waited_for():
    arms = [arm("ours", 0.36), arm("steps", 0.40), arm("wrong")]
    assert verdict(arms) == (
        "EQA test below the paper's at the quick budget under the paper's stated model; 'wrong' still to run."
    )
    assert "| wrong | no run yet | — | — | — |" in finding(arms, PAPER, BLIND, "quick")


@pytest.mark.parametrize(
    ("values", "expected"),
    [
        ((0.58,), "EQA test reproduced at the quick budget under the paper's stated model."),
        # 0.52: se sqrt(0.52 * 0.48 / 100) = 0.050, 0.06 below < 1.645 se = 0.082
        ((0.52,), "EQA test within the error of the paper's at the quick budget: neither reproduced nor refuted."),
        # three seeds 0.38 / 0.35 / 0.58 (Table 2's): mean 0.4367, sample sd 0.1250, se 0.0722; 0.143 > 0.119
        ((0.38, 0.35, 0.58), "EQA test not reproduced at the quick budget under the paper's stated model."),
    ],
)
def test_the_stated_model_is_held_to_the_papers_number_by_the_threshold_rule(values, expected):
    assert verdict([arm("ours", *values), arm("steps", 0.40)]) == expected


def test_no_run_of_the_stated_model_waits():
    lines = finding([arm("ours"), arm("steps", 0.40)], PAPER, BLIND, "quick")
    assert not any(line.startswith("**") for line in lines)
    assert "Waiting for Table 2's Dual-Attention, Doom Easy, Aux at the 'quick' profile." in lines


def test_the_arms_are_the_experiments_rows_read_from_the_results(tmp_path):
    """The first row borrows Table 2's Dual-Attention runs (three seeds); an arm's run is read from the experiment's
    own results; an arm with none is empty."""
    from emml.report.plan import plan_report

    root = tmp_path / "results"
    fake_results("table2", root, value=lambda spec: 0.3 + 0.1 * spec.seed)  # EQA test 0.3 / 0.4 / 0.5, train alike
    plan = plan_report(eqa_test.EXPERIMENT, PROFILE, root)
    steps = next(r for r in plan.runs if r.spec.row == "answer CE on answer steps only" and r.spec.seed == 0)
    (root / "eqa_answer").mkdir()
    pd.DataFrame(
        [
            dict(run_name=steps.name, table="eqa_answer", model="dual_attention", difficulty="easy", aux=True, seed=0,
                 profile=PROFILE, frames=1_500_160, eval_episodes=500, sgn_test=0.9, eqa_train=0.7, eqa_test=0.37)
        ]
    ).to_csv(root / "eqa_answer" / f"{PROFILE}.csv", index=False)  # fmt: skip
    ours, answer_steps, wrong = read_arms(plan.profile, root)
    assert ours.label == "answer CE on every EQA step, wrong 0 (ours)" and wrong.label == "wrong outcome -0.2"
    assert [(s.seed, s.value, s.episodes, s.train) for s in ours.scores] == [(0, 0.3, 100, 0.3), (1, 0.4, 100, 0.4),
                                                                            (2, 0.5, 100, 0.5)]  # fmt: skip
    assert [(s.run, s.value, s.episodes, s.train) for s in answer_steps.scores] == [(steps.name, 0.37, 500, 0.7)]
    assert wrong.scores == []


def test_the_papers_number_is_table_2s():
    assert eqa_test.paper_value() == 0.58
