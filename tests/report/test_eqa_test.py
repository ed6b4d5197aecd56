"""The claims page's EQA box (issues 62, 81, 82): EQA test under the paper's stated model, per seed with its question
gate, against the paper's number and chance, and the answer path's other rows per seed. Every verdict worked out by
hand from the threshold rule (Z = 1.645 standard errors; one seed: binomial only)."""

import pandas as pd
import pytest

from emml.experiments.claims.evidence import Chance, Score
from emml.report import eqa_test
from emml.report.eqa_test import Arm, Gate, finding, read_arms, read_gate
from tests.report.test_tables import PROFILE, fake_results

CHANCE = Chance({("easy", "eqa_test"): 0.45}, "the task's ceiling")
PAPER = 0.58


def arm(label, *values, episodes=100, experiment="experiments/eqa_answer", gates=None):
    scores = [Score(f"{label}-s{i}", i, v, episodes, 1_500_160, 0.8) for i, v in enumerate(values)]
    return Arm(label, scores, {f"{label}-s{i}": g for i, g in (gates or {}).items()}, experiment)


def verdict(arms) -> str:
    lines = finding(arms, PAPER, CHANCE, "quick")
    (bold,) = [line for line in lines if line.startswith("**")]
    return bold.split("**")[1]


def test_below_the_paper_beyond_the_error_and_no_arm_above_chance_is_not_reproduced():
    # 0.36 on 100 episodes: se sqrt(0.36 * 0.64 / 100) = 0.048, 0.58 - 0.36 = 0.22 > 1.645 * 0.048 = 0.079
    arms = [arm("ours", 0.36), arm("steps", 0.40), arm("wrong", 0.45)]  # 0.45 is chance itself: not above
    assert verdict(arms) == "EQA test not reproduced at the quick budget under the paper's stated model."
    lines = finding(arms, PAPER, CHANCE, "quick")
    assert "| 0 | 0.360 | 0.800 | not above | — | — |" in lines  # the stated model's seed, no gate figures yet
    assert "| eqa_answer · wrong | 0.450 (s0) | 0.450 | — | not above |" in lines
    assert any("Chance is 0.450 (the task's ceiling): none of its 1 seeds above it." in line for line in lines)


def test_an_arm_above_chance_on_one_seed_is_named_and_runs_its_seeds_first():
    arms = [arm("ours", 0.36), arm("steps", 0.40), arm("wrong", 0.46)]
    assert verdict(arms) == (
        "EQA test below the paper's at the quick budget under the paper's stated model; 'wrong' clears chance: its "
        "seeds 1 and 2 before anything changes."
    )
    assert "| eqa_answer · wrong | 0.460 (s0) | 0.460 | — | above |" in finding(arms, PAPER, CHANCE, "quick")


def test_an_arm_above_chance_on_three_seeds_is_named_as_a_choice_the_paper_does_not_state():
    arms = [arm("ours", 0.36), arm("gate", 0.88, 0.86, 0.76, experiment="experiments/eqa_gate"), arm("wrong", 0.3)]
    assert verdict(arms) == (
        "EQA test not reproduced at the quick budget under the paper's stated model; reached by a choice the paper "
        "does not state: 'gate' (mean 0.833 on 3 seeds)."
    )
    lines = finding(arms, PAPER, CHANCE, "quick")
    assert "| eqa_gate · gate | 0.880 (s0) · 0.860 (s1) · 0.760 (s2) | 0.833 | — | above |" in lines


def test_every_seed_of_the_stated_model_shows_its_eqa_test_and_its_gate():
    """Table 2's three seeds as measured: seed 2's gate opens the colours on an unseen subject and scores above
    chance; each row its own seed's gate."""
    gates = {0: Gate(0.692, 0.180, 0.999, 1), 1: Gate(0.802, 0.489, 0.991, 0), 2: Gate(0.9652, 0.9152, 0.996, 0)}
    stated = arm("ours", 0.380, 0.348, 0.578, episodes=500, gates=gates)
    variant = arm("mean", 0.184, gates={0: Gate(0.967, 0.968, 0.966, 3)}, experiment="experiments/eqa_readout")
    lines = finding([stated, variant], PAPER, CHANCE, "quick")
    assert "| 0 | 0.380 | 0.800 | not above | 0.69 (colour 0.18 · object 1.00) | 1 |" in lines
    assert "| 1 | 0.348 | 0.800 | not above | 0.80 (colour 0.49 · object 0.99) | 0 |" in lines
    assert "| 2 | 0.578 | 0.800 | above | 0.97 (colour 0.92 · object 1.00) | 0 |" in lines
    assert "| eqa_readout · mean | 0.184 (s0) | 0.184 | 0.97 (s0) | not above |" in lines
    (bold,) = [line for line in lines if line.startswith("**")]
    # chance 0.45: seeds 0 (0.380) and 1 (0.348) below it, seed 2 above
    assert bold.endswith("Chance is 0.450 (the task's ceiling): 1 of its 3 seeds above it (0.578 (s2)).")


def test_chance_is_the_one_passed_in():
    stated = arm("ours", 0.380, 0.348, 0.578, episodes=500)
    for ceiling, above in ((0.5625, "1 of its 3 seeds above it (0.578 (s2))"), (0.34, "3 of its 3 seeds above it")):
        lines = finding([stated, arm("steps", 0.4)], PAPER, Chance({("easy", "eqa_test"): ceiling}, "x"), "quick")
        (bold,) = [line for line in lines if line.startswith("**")]
        assert f"Chance is {ceiling:.3f} (x): {above}" in bold


def test_the_stated_model_above_chance_is_no_arm_to_run():
    # 0.47 on 1,000 episodes: se 0.0158, 0.11 below the paper > 1.645 se = 0.026; above 0.45, but it is the model
    arms = [arm("ours", 0.47, episodes=1000), arm("steps", 0.40)]
    assert verdict(arms) == "EQA test not reproduced at the quick budget under the paper's stated model."


def test_an_arm_without_a_run_is_waited_for():
    arms = [arm("ours", 0.36), arm("steps", 0.40), arm("wrong")]
    assert verdict(arms) == (
        "EQA test below the paper's at the quick budget under the paper's stated model; 'wrong' still to run."
    )
    assert "| eqa_answer · wrong | no run yet | — | — | — |" in finding(arms, PAPER, CHANCE, "quick")


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
    lines = finding([arm("ours"), arm("steps", 0.40)], PAPER, CHANCE, "quick")
    assert not any(line.startswith("**") for line in lines)
    assert "Waiting for Table 2's Dual-Attention, Doom Easy, Aux at the 'quick' profile." in lines


def test_a_runs_gate_is_its_last_point(tmp_path):
    path = tmp_path / "metrics.csv"
    path.write_text(
        "step,key,value\n"
        "100,diag/gate_on_attribute,0.5\n100,diag/gate_on_color,0.1\n100,diag/gate_dead,2.0\n100,eval/eqa_test,0.3\n"
        "200,diag/gate_on_attribute,0.9\n200,diag/gate_on_color,0.8\n200,diag/gate_on_object,1.0\n"
        "200,diag/gate_dead,0.0\n"
    )
    assert read_gate(path) == Gate(0.9, 0.8, 1.0, 0)
    path.write_text("step,key,value\n100,eval/eqa_test,0.3\n")
    assert read_gate(path) is None  # a run from before issue 82, not filled
    assert read_gate(tmp_path / "absent.csv") is None
    path.write_text("step,key,value\nnot a point\n")
    assert read_gate(path) is None  # a damaged mirror costs its own run's figures only


def test_the_arms_are_the_experiments_rows_read_from_the_results_with_their_runs_gates(tmp_path):
    """The stated model borrows Table 2's Dual-Attention runs (three seeds), each with its gate from its run dir
    under Table 2's; an arm's run is read from its experiment's own results; then every other experiment's rows but
    its first (the stated model again)."""
    from emml.report.plan import plan_report

    root, runs = tmp_path / "results", tmp_path / "runs"
    fake_results("table2", root, value=lambda spec: 0.3 + 0.1 * spec.seed)  # EQA test 0.3 / 0.4 / 0.5, train alike
    plan = plan_report(eqa_test.EXPERIMENT, PROFILE, root)
    steps = next(r for r in plan.runs if r.spec.row == "answer CE on answer steps only" and r.spec.seed == 0)
    stated_s2 = next(r for r in plan.runs if r.spec.row == plan.table.rows[0].label and r.spec.seed == 2)
    (root / "eqa_answer").mkdir()
    pd.DataFrame(
        [
            dict(run_name=steps.name, table="eqa_answer", model="dual_attention", difficulty="easy", aux=True, seed=0,
                 profile=PROFILE, frames=1_500_160, eval_episodes=500, sgn_test=0.9, eqa_train=0.7, eqa_test=0.37)
        ]
    ).to_csv(root / "eqa_answer" / f"{PROFILE}.csv", index=False)  # fmt: skip
    run_dir = runs / "table2" / stated_s2.name
    run_dir.mkdir(parents=True)
    (run_dir / "metrics.csv").write_text(
        "step,key,value\n9,diag/gate_on_attribute,0.97\n9,diag/gate_on_color,0.92\n9,diag/gate_dead,0.0\n"
    )
    arms = read_arms(plan.profile, root, runs)
    ours, answer_steps, wrong, *others = arms
    assert ours.label == "answer CE on every EQA step, wrong 0 (ours)" and wrong.label == "wrong outcome -0.2"
    assert [(s.seed, s.value, s.episodes, s.train) for s in ours.scores] == [(0, 0.3, 100, 0.3), (1, 0.4, 100, 0.4),
                                                                            (2, 0.5, 100, 0.5)]  # fmt: skip
    assert ours.gates == {stated_s2.name: Gate(0.97, 0.92, None, 0)}  # seed 2's run dir only has them
    assert [(s.run, s.value, s.episodes, s.train) for s in answer_steps.scores] == [(steps.name, 0.37, 500, 0.7)]
    assert wrong.scores == [] and answer_steps.gates == {}
    gate_rows = [a.label for a in plan_report("experiments/eqa_gate", PROFILE, root).table.rows][1:]
    readout_rows = [a.label for a in plan_report("experiments/eqa_readout", PROFILE, root).table.rows][1:]
    assert [(a.experiment, a.label) for a in others] == [
        *(("experiments/eqa_gate", label) for label in gate_rows),
        *(("experiments/eqa_readout", label) for label in readout_rows),
    ]
    assert all(not a.scores for a in others)  # no results of theirs in this root


def test_the_papers_number_is_table_2s():
    assert eqa_test.paper_value() == 0.58


def test_a_runs_gate_keeps_its_history_a_step_logged_twice_keeping_its_last_value(tmp_path):
    """`Gate.history`: each figure's points by step, sorted; a step logged again (a resumed run's repeated
    evaluation) keeps its last value; the Gate's values are those of the last step."""
    path = tmp_path / "metrics.csv"
    path.write_text(
        "step,key,value\n"
        "200,diag/gate_on_color,0.5\n200,diag/gate_on_attribute,0.6\n200,diag/gate_dead,1.0\n"
        "100,diag/gate_on_color,0.1\n100,diag/gate_on_attribute,0.2\n100,diag/gate_dead,2.0\n"
        "200,diag/gate_on_color,0.7\n"
    )
    gate = read_gate(path)
    assert gate == Gate(0.6, 0.7, None, 1)
    assert gate.history["diag/gate_on_color"] == ((100, 0.1), (200, 0.7))
    assert gate.history["diag/gate_dead"] == ((100, 2.0), (200, 1.0))
    assert "diag/gate_on_object" not in gate.history


def test_the_gate_figure_draws_a_line_per_seed_with_a_gate_in_each_panel():
    """One line per seed that has points, in the colour panel and the object panel, labelled with its EQA test; a
    seed without gate figures is left out; no seed with them, no figure."""
    import matplotlib.pyplot as plt

    from emml.report import gate_figure

    history = {
        "diag/gate_on_color": ((500_000, 0.2), (1_000_000, 0.9)),
        "diag/gate_on_object": ((500_000, 0.99), (1_000_000, 1.0)),
    }
    stated = arm("ours", 0.38, 0.35, 0.58)
    stated = Arm(stated.label, stated.scores, {stated.scores[2].run: Gate(0.95, 0.9, 1.0, 0, history),
                                               stated.scores[0].run: Gate(0.7, 0.18, 1.0, 1, {})})  # fmt: skip
    fig = gate_figure.draw(stated)
    colour, objects = fig.axes
    assert [line.get_label() for line in colour.lines] == ["seed 2 (EQA test 0.58)"]
    assert [tuple(colour.lines[0].get_xdata()), tuple(colour.lines[0].get_ydata())] == [(500_000, 1_000_000),
                                                                                      (0.2, 0.9)]  # fmt: skip
    assert tuple(objects.lines[0].get_ydata()) == (0.99, 1.0)
    assert colour.get_title() == "colour questions" and objects.get_title() == "object questions"
    plt.close(fig)
    assert gate_figure.draw(arm("ours", 0.38)) is None and gate_figure.figure(arm("ours", 0.38), []) == []


def test_the_box_shows_the_gate_figure_only_when_one_was_drawn():
    image = "![The stated model's question gate over training, per seed](claims-quick-gate.png)"
    arms = [arm("ours", 0.38, 0.35, 0.58), arm("steps", 0.40)]
    assert image in finding(arms, PAPER, CHANCE, "quick", "claims-quick-gate.png")
    assert not any("gate over training" in line for line in finding(arms, PAPER, CHANCE, "quick"))
