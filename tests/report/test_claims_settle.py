"""What the claims page reads to weigh a reversal (emml/report/claims_settle.py, issue 81 items 3 and 5): the
nearest cell whose spread a one-seed row borrows, the run that gives a cell its next seed, the warm-up's
paper-literal twin, and the settling runs with their campaign step."""

import pytest

from emml.experiments.claims.evidence import REVERSED, Check, Score
from emml.report.claims_settle import (
    borrow,
    literal_of,
    nearest,
    next_seed,
    settle_costs,
    spread_of,
    warm_frames,
)
from emml.report.plan import plan_report
from tests.report.test_tables import PROFILE


def label(d, a):
    return f"{d} {'Aux' if a else 'No Aux'}"


def test_the_nearest_cell_is_the_same_difficulty_first_then_the_same_aux():
    spreads = {
        ("DA", "hard", True, "eqa_test"): (0.01, 2),
        ("DA", "easy", True, "eqa_test"): (0.02, 3),
        ("DA", "easy", False, "sgn_test"): (0.03, 2),  # another metric: never
        ("GA", "easy", True, "eqa_test"): (0.04, 2),  # another row: never
    }
    assert nearest(("DA", "easy", False, "eqa_test"), spreads) == ("DA", "easy", True, "eqa_test")
    assert nearest(("DA", "hard", False, "eqa_test"), spreads) == ("DA", "hard", True, "eqa_test")
    # the same difficulty before the same aux: Hard · No Aux is the same aux, Easy · Aux the same difficulty
    both = {**spreads, ("DA", "hard", False, "eqa_test"): (0.05, 2)}
    assert nearest(("DA", "easy", False, "eqa_test"), both) == ("DA", "easy", True, "eqa_test")
    del spreads[("DA", "hard", True, "eqa_test")]
    assert nearest(("DA", "hard", True, "eqa_test"), spreads) == ("DA", "easy", True, "eqa_test")  # same aux
    assert nearest(("PACMAN", "easy", True, "eqa_test"), spreads) is None


def test_a_one_seed_cell_borrows_its_nearest_spread_and_a_cell_with_two_keeps_its_own():
    """DA Easy Aux on 3 seeds 0.38 / 0.348 / 0.578 (sample variance 0.03104 / 2 = 0.01552); its Easy No Aux cell on
    one seed borrows it, named; a cell with two seeds and a row with no spread anywhere borrow nothing."""
    values = [0.38, 0.348, 0.578]
    assert spread_of(values) == pytest.approx(0.015521, abs=1e-6) and spread_of([0.4]) is None
    spreads = {("DA", "easy", True, "eqa_test"): (spread_of(values), 3)}
    one = Score("da-noaux-s0", 0, 0.3, 500, 1, 0.9, 0.3)
    two = [Score("da-aux-s0", 0, 0.38, 500, 1, 0.9, 0.3), Score("da-aux-s1", 1, 0.35, 500, 1, 0.9, 0.3)]
    lone = Score("ga-s0", 0, 0.3, 500, 1, 0.9, 0.3)
    scores = {
        ("DA", "easy", False, "eqa_test"): [one],
        ("DA", "easy", True, "eqa_test"): two,
        ("GA", "easy", True, "eqa_test"): [lone],
    }
    out = borrow(scores, spreads, label)
    (got,) = out[("DA", "easy", False, "eqa_test")]
    assert got.borrowed == pytest.approx(0.015521, abs=1e-6) and got.borrowed_from == "DA, easy Aux (3 seeds)"
    assert out[("DA", "easy", True, "eqa_test")] == two and out[("GA", "easy", True, "eqa_test")] == [lone]


def test_the_next_seed_is_the_first_declared_run_missing_else_the_seed_after_the_last():
    plan = plan_report("table2", PROFILE)
    seeds = [r.spec.seed for r in plan.cell_runs("Text only", "easy", True, "eqa_test")]
    assert seeds[:2] == [0, 1]
    found = ["text_only-easy-aux-s0-quick"]
    assert next_seed(plan, "Text only", "easy", True, "eqa_test", found) == "table2/text_only-easy-aux-s1-quick"
    every = [r.name for r in plan.cell_runs("Text only", "easy", True, "eqa_test")]
    after = f"table2/text_only-easy-aux-s{max(seeds) + 1}-quick"
    assert next_seed(plan, "Text only", "easy", True, "eqa_test", every) == after


def test_the_warm_up_and_its_paper_literal_twin_are_read_from_the_run_names():
    assert literal_of("dual_attention-easy-noaux-warm400000-s0-quick") == "dual_attention-easy-noaux-s0-quick"
    assert literal_of("dual_attention-easy-aux-s0-quick") is None
    assert warm_frames(["a-noaux-warm400000-s0-quick", "a-noaux-warm400000-s1-quick"]) == 400000
    assert warm_frames(["a-noaux-warm400000-s0-quick", "a-noaux-s1-quick"]) is None  # not every run
    assert warm_frames([]) is None


def test_each_settling_run_is_named_once_with_its_campaign_step():
    c = Check("EQA test, Easy · No Aux", "DA > Text only", REVERSED, "")
    c.unsettled, c.settle_by = "reversed on 1 seed", ["table2/text_only-easy-noaux-s1-quick", "more frames"]
    settled = Check("w", "x", REVERSED, "", settle_by=["table2/never-shown"])  # settled: nothing to run
    costs = {("table2", "text_only-easy-noaux-s1-quick"): "campaign step `settle`, to do: ~0.8 h here"}
    assert settle_costs([c, c, settled], costs) == [
        "`table2/text_only-easy-noaux-s1-quick` (EQA test, Easy · No Aux: DA > Text only): campaign step `settle`, "
        "to do: ~0.8 h here",
        "more frames for the runs of EQA test, Easy · No Aux: DA > Text only (no campaign step trains them further)",
    ]
    assert settle_costs([c], {})[0].endswith("in no step of the campaign")


def test_a_runs_curve_is_read_for_its_scores_metric_and_again_when_its_file_changes(tmp_path):
    from emml.report.claims_settle import Curves

    path = tmp_path / "metrics.csv"
    path.write_text("step,key,value\n100,eval/sgn_test,0.2\n200,eval/sgn_test,0.4\n200,diag/detector_ap,0.3\n")
    curves = Curves({"r": tmp_path})
    score = Score("r", 0, 0.4, 500, 200, 0.9, 0.3, metric="sgn_test")
    assert curves(score) == {100: 0.2, 200: 0.4}
    assert curves(Score("r", 0, 0.3, 0, 200, 0.9, 0.0, metric="diag/detector_ap")) == {200: 0.3}
    assert curves(Score("r", 0, 0.4, 500, 200, metric="eqa_test")) is None  # no point of that key
    assert curves(Score("other", 0, 0.4, 500, 200, metric="sgn_test")) is None  # not a run of the claim's cells
    path.write_text("step,key,value\n100,eval/sgn_test,0.25\n200,eval/sgn_test,0.45\n300,eval/sgn_test,0.5\n")
    assert curves(score) == {100: 0.25, 200: 0.45, 300: 0.5}


def test_the_paper_literal_run_is_found_beside_a_warm_up_cell_in_any_results_csv_of_the_profile(tmp_path):
    """Table 2's Dual-Attention No Aux runs trained under the warm-up; its no-warm-up twin is in Table 2's CSV, w/o
    GA2's in an experiment's (noaux_schedule): each found, with its number for the cell's metric."""
    from types import SimpleNamespace

    import pandas as pd

    from emml.config.profiles import resolve_profile
    from emml.report.claims_settle import literal

    root = tmp_path / "results"
    for table, name, value in (
        ("table2", "dual_attention-easy-noaux-s0-quick", 0.194),
        ("noaux_schedule", "da_no_ga2-easy-noaux-s0-quick", 0.45),
    ):
        (root / table).mkdir(parents=True)
        pd.DataFrame([{"run_name": name, "table": table, "sgn_test": value}]).to_csv(root / table / "quick.csv")
    plan = SimpleNamespace(profile=resolve_profile("quick"), results_root=root)

    def entry(row, runs):
        return {"row": row, "setting": "Easy · No Aux", "metric": "SGN test", "runs": runs, "column": "sgn_test"}

    evidence = [
        entry("Dual-Attention", ["dual_attention-easy-noaux-warm400000-s0-quick"]),
        entry("w/o GA2", ["da_no_ga2-easy-noaux-warm400000-s0-quick"]),
        entry("GA", ["ga-easy-noaux-warm400000-s0-quick"]),  # no twin trained: nothing beside it
        entry("Text only", ["text_only-easy-noaux-s0-quick"]),  # no warm-up: nothing to set beside it
    ]
    assert literal(evidence, plan) == [
        {"row": "Dual-Attention", "setting": "Easy · No Aux", "metric": "SGN test",
         "run": "table2/dual_attention-easy-noaux-s0-quick", "value": 0.194},
        {"row": "w/o GA2", "setting": "Easy · No Aux", "metric": "SGN test",
         "run": "noaux_schedule/da_no_ga2-easy-noaux-s0-quick", "value": 0.45},
    ]  # fmt: skip
    assert literal(evidence[3:], plan) == []
