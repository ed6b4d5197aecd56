"""How a claim's cells are read and judged (emml/report/claims.py: gather, judge, decide, decide_paper, the curve
scores) on FIXTURES (made-up results rows and metrics.csv files in tmp_path, never results/), each expected Score
and field worked out by hand (issue 66: written against the survivors of `make mutate MUTATE=report/claims`)."""

import math
from dataclasses import replace

import pandas as pd
import pytest

import emml.report.claims as claims
from emml.config.paths import project_root
from emml.config.profiles import profile_seeds, resolve_profile
from emml.experiments.claims.evidence import LEAVE, Chance, Score
from emml.experiments.tables import load_table
from emml.report.claims import (
    BUDGET,
    PAPER,
    UNTESTABLE,
    Evidence,
    _tables_with_runs,
    decide,
    decide_paper,
    gather,
    judge,
)
from emml.report.claims_settle import isnan
from emml.report.plan import plan_report
from tests.report.test_claims_page import CLAIMS, da_ahead, edit
from tests.report.test_efficiency import write_curves, write_points
from tests.report.test_tables import PROFILE, fake_results

COLUMNS = ("sgn_train", "sgn_test", "eqa_train", "eqa_test")
CHANCE = Chance({(d, m): v for d, v in (("easy", 0.5), ("hard", 0.7)) for m in COLUMNS}, "made up")
"""Chance 0.5 in Easy and 0.7 in Hard (both above every uniform floor): bars 0.6 and 0.8."""
DA = [f"dual_attention-easy-aux-s{s}-quick" for s in (0, 1, 2, 3, 4)]
"""Table 2's Dual-Attention, Easy · Aux, at the quick profile: its seeds and its more_seeds 3-4."""


def scores(ev: Evidence, row: str, difficulty: str, aux: bool, metric: str) -> list[tuple]:
    return [
        (s.run, s.seed, round(s.value, 6), s.episodes, s.frames, s.train if s.train is None else round(s.train, 6),
         round(s.bar, 6), s.every)
        for s in ev.scores[(row, difficulty, aux, metric)]
    ]  # fmt: skip


def test_each_run_is_one_score_with_its_seed_episodes_frames_and_learning_bar(tmp_path):
    """Dual-Attention's five Easy · Aux runs score 0.5 … 0.9 (train the same) on 100 episodes each; with the chance
    given, its bar is Easy's 0.5 + LEAVE (Hard's would be 0.8; the fixture's own Text only rows 0.3)."""
    root = tmp_path / "results"
    frames = int(fake_results("table2", root, value=da_ahead)["frames"].iloc[0])
    ev = gather(CLAIMS["da-best-easy-aux"], plan_report("table2", PROFILE, root), CHANCE)
    assert scores(ev, "Dual-Attention", "easy", True, "sgn_test") == [
        (DA[s], s, round(0.5 + 0.1 * s, 6), 100, frames, round(0.5 + 0.1 * s, 6), 0.5 + LEAVE, 0) for s in range(5)
    ]
    assert scores(ev, "Text only", "easy", True, "eqa_test")[0][6] == -math.inf  # the blind row is the chance line
    (entry,) = [e for e in ev.evidence if e["row"] == "Dual-Attention" and e["metric"] == "SGN test"]
    assert entry == {
        "row": "Dual-Attention",
        "setting": "Easy · Aux",
        "metric": "SGN test",
        "values": {0: 0.5, 1: 0.6, 2: 0.7, 3: 0.8, 4: 0.9},
        "shown": {0: "0.500", 1: "0.600", 2: "0.700", 3: "0.800", 4: "0.900"},
        "declared": 5,
        "runs": DA,
        "column": "sgn_test",
    }
    assert ev.frames == {frames} and ev.missing == []
    assert ev.owners == {
        run.name: "table2" for run in plan_report("table2", PROFILE, root).runs if run.spec.difficulty == "easy"
        and run.spec.aux
    }  # fmt: skip


def test_without_a_chance_given_the_bar_is_the_blind_prior_of_the_results_read(tmp_path):
    from emml.report.chance import blind_prior

    root = tmp_path / "results"
    fake_results("table2", root, value=lambda spec: 0.6 if spec.model == "text_only" else 0.9)
    ev = gather(CLAIMS["da-best-easy-aux"], plan_report("table2", PROFILE, root))
    bar = blind_prior(resolve_profile(PROFILE), root).bar("sgn_train", "easy")
    assert {round(s[6], 6) for s in scores(ev, "Dual-Attention", "easy", True, "sgn_test")} == {round(bar, 6)}


def test_a_run_without_its_training_score_is_named_and_the_next_seed_still_read(tmp_path):
    root = tmp_path / "results"
    fake_results("table2", root, value=da_ahead)
    edit(root, "table2", "dual_attention-hard-aux-s0-quick", sgn_train=float("nan"))
    ev = gather(CLAIMS["da-best-hard-train"], plan_report("table2", PROFILE, root), CHANCE)
    assert ev.missing == ["dual_attention-hard-aux-s0-quick (no sgn_train in its results row)"]
    assert [s[:3] for s in scores(ev, "Dual-Attention", "hard", True, "sgn_train")] == [
        ("dual_attention-hard-aux-s1-quick", 1, 0.6),
        ("dual_attention-hard-aux-s2-quick", 2, 0.7),
    ]
    # a test cell's run without its training score is read, and read as having none (not NaN)
    edit(root, "table2", DA[1], sgn_train=float("nan"))
    ev = gather(CLAIMS["da-best-easy-aux"], plan_report("table2", PROFILE, root), CHANCE)
    assert [s[5] for s in scores(ev, "Dual-Attention", "easy", True, "sgn_test")] == [0.5, None, 0.7, 0.8, 0.9]


def test_nan_is_what_cannot_be_read_as_a_number():
    assert isnan(None) and isnan("n/a") and isnan(float("nan"))
    assert not isnan("0.25") and not isnan(0)


def test_judge_keeps_the_claim_and_source_and_orders_the_cells_by_metric_then_difficulty_aux_first(tmp_path):
    root = tmp_path / "results"
    fake_results("table2", root, value=da_ahead)
    claim = replace(CLAIMS["da-best-easy-aux"], where={}, metrics=("eqa_test", "sgn_test"))
    ev = gather(claim, plan_report("table2", PROFILE, root), CHANCE)
    ev.owners = {"x-s0-quick": "table9"}
    d = judge(claim, ev, "quick")
    assert (d.id, d.text, d.source, d.kind, d.table, d.profile) == (
        "da-best-easy-aux", claim.text, claim.source, "best", "table2", "quick"
    )  # fmt: skip
    assert d.owners == {"x-s0-quick": "table9"} and d.frames == sorted(ev.frames) and d.seeds == 3
    settings = ("Easy · Aux", "Easy · No Aux", "Hard · Aux", "Hard · No Aux")
    assert [(c.metric, c.setting) for c in d.checks][::6] == [
        (m, s) for m in ("EQA test", "SGN test") for s in settings
    ]  # six comparisons (Dual-Attention against each other row) per cell
    assert judge(claim, Evidence(), "quick").seeds == 0  # nothing present: no seed


def test_a_single_subject_unlearned_with_a_cell_missing_is_at_this_budget_several_subjects_wait(tmp_path):
    """'best' has one subject: Dual-Attention unlearned (train 0.1 under the bar 0.6) and ahead where compared, with
    GA's cell empty, is not supported at this budget. 'aux_helps' has several: the row unlearned with its No Aux
    cell empty waits for it."""
    claim = CLAIMS["da-best-easy-aux"]
    ahead = [Score("d", 0, 0.9, 500, 1, 0.1, 0.6)]
    other = [Score("o", 0, 0.1, 500, 1, 0.9, 0.6)]
    cells = {(r.label, "easy", True, m): other for r in load_table("table2").rows for m in claim.metrics}
    cells |= {("Dual-Attention", "easy", True, m): ahead for m in claim.metrics} | {
        ("GA", "easy", True, "sgn_test"): []
    }
    assert judge(claim, Evidence(scores=cells), "quick").status == BUDGET
    several = CLAIMS["single-task-sgn-aux"]
    cells = {("DA Single-Task", "easy", True, "sgn_test"): ahead, ("DA Single-Task", "easy", False, "sgn_test"): []}
    assert judge(several, Evidence(scores=cells), "quick").status == UNTESTABLE


def test_decide_plans_each_table_once_reads_the_chance_given_and_names_its_profile(tmp_path):
    root = tmp_path / "results"
    fake_results("table2", root, value=da_ahead)
    plans: dict = {}
    d = decide(CLAIMS["da-best-easy-aux"], PROFILE, root, chance=CHANCE, plans=plans)
    assert d.profile == PROFILE and set(plans) == {"table2"}
    plan = plans["table2"]
    decide(CLAIMS["da-best-hard-aux"], PROFILE, root, plans=plans)
    assert plans["table2"] is plan  # the second claim of the table reuses its plan
    assert {round(s.bar, 6) for c in d.checks for s in c.high} == {0.5 + LEAVE}  # CHANCE's Easy bar
    assert decide_paper(CLAIMS["da-best-easy-aux"]).profile == PAPER


def speed(tmp_path):
    """FIXTURE: Table 3 and 2 results (every run learned) and curves leaving chance at 0.3 of the frames."""
    results, runs = tmp_path / "results", tmp_path / "runs"
    frames = int(fake_results("table3", results, value=lambda spec: 0.9)["frames"].iloc[0])
    fake_results("table2", results, value=lambda spec: 0.25 if spec.model == "text_only" else 0.9)
    write_curves(runs, "table3", lambda s: 0.3)
    write_curves(runs, "table2", lambda s: 0.3)
    return results, runs, frames


def test_a_crossing_is_a_score_of_frames_known_to_the_evaluations_gap(tmp_path):
    results, runs, frames = speed(tmp_path)
    plan = plan_report("table3", PROFILE, results, runs)
    ev = gather(CLAIMS["shaping-speed"], plan)
    name = "dual_attention-easy-aux-noshaping-s0-quick"
    (first, *_) = scores(ev, "w/o Reward Shaping", "easy", True, "sgn_train")
    steps = [frames * i // 10 for i in range(11)]
    assert first == (name, 0, float(steps[3]), 0, frames, None, -math.inf, max(b - a for a, b in zip(steps, steps[1:])))
    # a chance no curve rises above (0.95 + LEAVE): nothing leaves it, not learned at this budget
    high = Chance({("easy", m): 0.95 for m in COLUMNS}, "made up")
    assert decide(CLAIMS["shaping-speed"], PROFILE, results, runs, chance=high).status == BUDGET
    # a run whose results row lacks the training column is still read from its curve
    edit(results, "table3", name, sgn_train=float("nan"))
    ev = gather(CLAIMS["shaping-speed"], plan_report("table3", PROFILE, results, runs))
    assert not [m for m in ev.missing if "noshaping" in m]  # (the fixture's curves leave out the more_seeds)
    assert scores(ev, "w/o Reward Shaping", "easy", True, "sgn_train")[0][:3] == first[:3]


def test_a_curve_that_stops_short_is_read_only_where_its_gap_reaches_the_runs_frames(tmp_path):
    """Evaluations every 0.1 of the frames: a curve one evaluation short still rules out a later crossing (its
    last + its gap reach the run's frames), two short does not; a crossing seen is read however short."""
    results, runs, frames = speed(tmp_path)
    spec = next(s for s in load_table("table3").runs([0]) if s.row == "w/o Reward Shaping" and s.aux)
    name = spec.run_name(PROFILE)
    claim = CLAIMS["shaping-speed"]

    def at(n: int, value: float) -> list[str]:
        return [f"{frames * i // 10},eval/sgn_train,{value}" for i in range(1, n + 1)]

    write_points(runs, spec, at(9, 0.2))  # never crossed, one evaluation short
    ev = gather(claim, plan_report("table3", PROFILE, results, runs))
    assert scores(ev, "w/o Reward Shaping", "easy", True, "sgn_train")[0][2] == math.inf
    write_points(runs, spec, at(8, 0.2))  # two short: a crossing after it cannot be ruled out
    ev = gather(claim, plan_report("table3", PROFILE, results, runs))
    assert [m for m in ev.missing if "noshaping" in m] == [f"{name} (no complete metrics.csv here)"]
    assert [s[1] for s in scores(ev, "w/o Reward Shaping", "easy", True, "sgn_train")] == [1, 2]  # the next seeds
    write_points(runs, spec, at(3, 0.2) + at(5, 0.95)[3:])  # crossed at 0.4, then the file stops
    ev = gather(claim, plan_report("table3", PROFILE, results, runs))
    assert scores(ev, "w/o Reward Shaping", "easy", True, "sgn_train")[0][2] == float(frames * 4 // 10)
    # a curve without the metric the claim reads: missing, named
    write_points(runs, spec, [f"{frames},eval/sgn_test,0.5"])
    ev = gather(claim, plan_report("table3", PROFILE, results, runs))
    assert [m for m in ev.missing if "noshaping" in m] == [f"{name} (no complete metrics.csv here)"]


def test_a_diagnostic_is_the_last_evaluations_figure_learned_on_either_training_split(tmp_path):
    """Dual-Attention No Aux's detector AP rises 0.1, 0.3, 0.4 over its curve: its number is the last, at the last
    step; it learned when either training score is above its Easy bar (0.6 here): SGN train 0.9 → margin 0.3."""
    results, runs = tmp_path / "results", tmp_path / "runs"
    fake_results("table2", results, value=lambda spec: 0.9)
    name = next(
        s.run_name(PROFILE)
        for s in load_table("table2").runs([0])
        if s.row == "Dual-Attention" and s.difficulty == "easy" and not s.aux
    )
    edit(results, "table2", name, eqa_train=0.65)
    claim = CLAIMS["attention-on-target"]
    claim = replace(claim, where={"difficulty": "easy", "aux": False}, key="diag/detector_ap")
    for spec in load_table("table2").runs(profile_seeds(PROFILE)):
        write_points(runs, spec, ["100,diag/detector_ap,0.1", "200,diag/detector_ap,0.3", "300,diag/detector_ap,0.4"])
    ev = gather(claim, plan_report("table2", PROFILE, results, runs), CHANCE)
    first = scores(ev, "Dual-Attention", "easy", False, "sgn_test")[0]
    assert first == (name, 0, 0.4, 0, 300, round(0.9 - (0.5 + LEAVE), 6), 0.0, 0)
    (entry,) = [e for e in ev.evidence if e["row"] == "Dual-Attention"]
    assert entry["shown"] == {0: "0.400", 1: "0.400", 2: "0.400"}
    # no training score at all: none (issue 85 item 4: left out of 'learned', no placeholder margin averaged in)
    edit(results, "table2", name, sgn_train=float("nan"), eqa_train=float("nan"))
    ev = gather(claim, plan_report("table2", PROFILE, results, runs), CHANCE)
    found = ev.scores[("Dual-Attention", "easy", False, "sgn_test")]
    assert found[0].train is None and [s.train is None for s in found[1:]] == [False] * (len(found) - 1)
    assert found[0].metric == "diag/detector_ap"  # its curve, for a reversal weighed for being settled


def test_a_transfer_rows_number_is_its_instructions_mean_over_all_their_episodes(tmp_path):
    """Table 4: a row averaging n instructions, each scored on the run's 100 episodes, is a rate of 100 × n."""
    root = tmp_path / "results"
    table = load_table("table4")
    plan = plan_report("table4", PROFILE, root)
    columns = [c for r in table.rows for c in table.cell_columns(r.label, "sgn_transfer")]
    rows = [
        {"run_name": run.name, "model": run.spec.model, "difficulty": run.spec.difficulty, "aux": run.spec.aux,
         "seed": run.spec.seed, "frames": 1000, "eval_episodes": 100, "sgn_train": 0.9, **dict.fromkeys(columns, 0.9)}
        for run in plan.runs
    ]  # fmt: skip
    (root / "table4").mkdir(parents=True)
    pd.DataFrame(rows).to_csv(root / "table4" / f"{PROFILE}.csv", index=False)
    ev = gather(CLAIMS["transfer-easy"], plan, CHANCE)
    several = next(r for r in table.rows if len(r.instructions) > 1)
    ((key, found),) = [(k, v) for k, v in ev.scores.items() if k[0] == several.label and k[1] == "easy"]
    assert {s.episodes for s in found} == {100 * len(several.instructions)}


def test_the_tables_with_runs_are_the_active_ones_with_a_finished_run_of_the_profile(tmp_path):
    """A placeholder table (a file of one's own, named by its path: sorted first) is skipped, not the end of the
    search; a table with no results CSV has no run."""
    root = tmp_path / "results"
    fake_results("table2", root, value=da_ahead)
    placeholder = tmp_path / "tableP.toml"
    placeholder.write_text('title = "t"\npaper_label = "tab:p"\nstatus = "placeholder"\n')
    names = {str(placeholder), "table2", "table4"}  # (Table 3 would have runs: its DA Multi-Task is Table 2's)
    assert _tables_with_runs(names, resolve_profile(PROFILE), root) == {"table2"}


def test_a_smoke_page_is_refused_in_the_committed_reports_before_anything_is_decided(monkeypatch):
    monkeypatch.setattr(claims, "decide_all", lambda *a: pytest.fail("decided before the folder was checked"))
    with pytest.raises(ValueError, match="'smoke' profile's numbers are not results"):
        claims.write_claims("smoke", project_root() / "reports")


def test_a_table_with_training_columns_of_its_own_reads_its_training_cells(tmp_path):
    """Table 5 has SGN train and EQA train columns of its own (Table 5 of the paper): a claim on sgn_train reads
    that column's cells, not the SGN test cells beside them (the gather's `m in columns` test; reading the test
    twin always, the mutant docs/testing.md once called equivalent, gives the test values 0.2 here)."""
    root = tmp_path / "results"
    fake_results("table5", root, value=lambda spec: 0.2)
    path = root / "table5" / f"{PROFILE}.csv"
    df = pd.read_csv(path)
    df["sgn_train"] = [0.3 + 0.01 * i for i in range(len(df))]  # each run's own training score, none 0.2
    df.to_csv(path, index=False)
    claim = replace(CLAIMS["house-da-best"], metrics=("sgn_train",))
    ev = gather(claim, plan_report("table5", PROFILE, root), CHANCE)
    train = dict(zip(df["run_name"], df["sgn_train"]))
    (entry,) = [e for e in ev.evidence if e["row"] == "Dual-Attention"]
    assert entry["metric"] == "SGN train" and entry["column"] == "sgn_train"
    read = [(s[0], s[2]) for s in scores(ev, "Dual-Attention", "house", False, "sgn_train")]
    assert read and read == [(run, round(train[run], 6)) for run in entry["runs"]]
    assert all(value > 0.25 for _, value in read)
