"""Sample efficiency and the speed and diagnostic claims (emml/report/efficiency.py, emml/report/claims.py, issue 49)
on a FIXTURE: made-up results rows and metrics.csv files in tmp_path (never results)."""

from emml.config.profiles import profile_seeds
from emml.experiments.claims.evidence import Chance
from emml.experiments.tables import load_table
from emml.report.claims import BUDGET, CONTRADICTED, INCONCLUSIVE, SUPPORTED, UNTESTABLE, decide
from emml.report.efficiency import (
    CURVE_KEYS,
    curves,
    first_crossing,
    level,
    markdown,
    run_efficiency,
    table_efficiency,
)
from emml.report.plan import plan_report
from emml.runs.curve import read_curve
from tests.report.test_claims_page import CLAIMS
from tests.report.test_tables import PROFILE, fake_results


def learned(spec) -> float:
    """FIXTURE: every run at 0.9 but the blind row (Text only) at 0.25, as a blind model scores SGN."""
    return 0.25 if spec.model == "text_only" else 0.9


def test_first_crossing_reads_chance_as_above_chance_plus_the_margin():
    points = [(100, 0.2), (200, 0.3), (300, 0.31), (400, 0.5), (500, 0.95)]
    assert first_crossing(points, "sgn_test", "chance") == 300  # 0.30 is not above 0.2 + 0.1
    assert first_crossing(points, "sgn_test", "0.5") == 400
    assert first_crossing(points, "sgn_test", "0.9") == 500
    assert first_crossing(points, "eqa_test", "chance") == 400  # EQA chance 1/3: above 0.433
    assert first_crossing(points[:2], "sgn_test", "0.9") is None
    assert first_crossing(points, "eqa_test", "chance", floor=0.45) == 500  # the blind prior 0.45: above 0.55


def write_curves(run_root, table: str, crossing, points: int = 10) -> None:
    """FIXTURE: every declared run of `table` a metrics.csv whose greedy accuracy jumps from chance to 0.95 at
    `crossing(spec)` (a fraction of its frames; None: never), evaluated `points` times evenly up to its frames."""
    for spec in load_table(table).runs(profile_seeds(PROFILE)):
        folder = run_root / spec.table / spec.run_name(PROFILE)
        folder.mkdir(parents=True, exist_ok=True)
        frames, at = spec.to_config(PROFILE).frames, crossing(spec)
        lines = ["step,key,value"]
        for i in range(1, points + 1):
            step = frames * i // points
            value = 0.95 if at is not None and i / points >= at else 0.2
            lines += [f"{step},eval/{m},{value}" for m in ("sgn_train", "sgn_test", "eqa_train", "eqa_test")]
            lines += [f"{step},diag/detector_ap,{0.1 if spec.model == 'dual_attention' and not spec.aux else 0.7}"]
            lines += [f"{step},diag/attention_on_target,0.8"]
        (folder / "metrics.csv").write_text("\n".join(lines) + "\n")


def test_a_speed_claim_is_decided_by_the_frames_to_leave_chance(tmp_path):
    results, runs = tmp_path / "results", tmp_path / "runs"
    fake_results("table3", results, value=learned)
    fake_results("table2", results, value=learned)  # Table 3's DA Multi-Task is Table 2's Dual-Attention
    claim = CLAIMS["shaping-speed"]
    write_curves(runs, "table3", lambda s: 0.6 if s.overrides.get("env.shaping") is False else 0.3)
    write_curves(runs, "table2", lambda s: 0.3)
    d = decide(claim, PROFILE, results, runs)
    assert d.status == SUPPORTED, d.phrase
    assert any(e["shown"] == {0: "0.45M", 1: "0.45M", 2: "0.45M"} for e in d.evidence)  # 0.3 of 1.5M frames
    write_curves(tmp_path / "r2", "table3", lambda s: 0.1)  # without shaping it leaves chance first, every seed
    write_curves(tmp_path / "r2", "table2", lambda s: 0.3)
    assert decide(claim, PROFILE, results, tmp_path / "r2").status == CONTRADICTED
    write_curves(tmp_path / "r4", "table3", lambda s: 0.4)  # one evaluation (0.15M) later: within the cadence
    write_curves(tmp_path / "r4", "table2", lambda s: 0.3)
    d = decide(claim, PROFILE, results, tmp_path / "r4")
    assert d.status == INCONCLUSIVE and "0.45M vs 0.60M" in d.phrase
    write_curves(tmp_path / "r3", "table3", lambda s: None)  # nothing leaves chance: not learned at this budget
    write_curves(tmp_path / "r3", "table2", lambda s: None)
    assert decide(claim, PROFILE, results, tmp_path / "r3").status == BUDGET
    d = decide(claim, PROFILE, results, tmp_path / "nowhere")  # no metrics.csv here: the runs are named
    assert d.status == UNTESTABLE and any("no complete metrics.csv here" in m for m in d.missing)


def test_the_channel_alignment_claim_reads_the_no_aux_run_detector_ap(tmp_path):
    results, runs = tmp_path / "results", tmp_path / "runs"
    fake_results("table2", results, value=learned)
    write_curves(runs, "table2", lambda s: 0.3)
    d = decide(CLAIMS["noaux-channels-align"], PROFILE, results, runs)
    assert d.status == CONTRADICTED and "diag/detector_ap" in d.phrase  # 0.1 against 0.5 × the Aux run's 0.7
    assert "0.5 × its Easy · Aux run's 0.70" in d.phrase
    fake_results("table2", tmp_path / "low", value=lambda spec: 0.2)  # at chance on its training split
    assert decide(CLAIMS["noaux-channels-align"], PROFILE, tmp_path / "low", runs).status == BUDGET
    assert decide(CLAIMS["attention-on-target"], PROFILE, results, tmp_path / "nowhere").status == UNTESTABLE


def test_the_table_page_lists_each_run_crossings(tmp_path):
    runs = tmp_path / "runs"
    write_curves(runs, "table3", lambda s: 0.3)
    spec = next(s for s in load_table("table3").runs([0]) if s.row == "w/o SA" and s.aux)
    eff = run_efficiency(spec, spec.run_name(PROFILE), runs)
    at = eff.last * 3 // 10
    assert eff.crossings["sgn_test"] == {"chance": at, "0.5": at, "0.9": at}
    text = markdown([eff, run_efficiency(spec, spec.run_name(PROFILE), tmp_path / "nowhere")])
    assert f"| w/o SA | Easy · Aux | 0 | {at / 1e6:.2f}M / {at / 1e6:.2f}M / {at / 1e6:.2f}M |" in text
    assert "no metrics.csv here" in text
    mirror = runs / spec.table / spec.run_name(PROFILE) / "metrics.csv"  # issue 65: a garbage line costs this run
    mirror.write_text(mirror.read_text().replace("\n", "\ngarbage\n", 2))
    damaged = run_efficiency(spec, spec.run_name(PROFILE), runs)
    assert not damaged.found and damaged.damaged and "| metrics.csv damaged |" in markdown([eff, damaged])


# Each part of the crossings worked out by hand (issue 66: mutation testing)

W_O_SA = next(s for s in load_table("table3").runs([0]) if s.row == "w/o SA" and s.aux)
"""A declared run: Table 3's w/o SA, Easy · Aux, seed 0."""


def write_points(run_root, spec, lines: list[str]) -> None:
    folder = run_root / spec.table / spec.run_name(PROFILE)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "metrics.csv").write_text("\n".join(["step,key,value", *lines]) + "\n")


def test_the_level_of_each_mark():
    assert level("sgn_test", "chance", 0.5) == 0.6 and level("eqa_test", "0.5", 0.45) == 0.5
    assert level("sgn_test", "0.9", 0.2) == 0.9


def test_leaving_chance_is_strictly_above_it_and_a_number_is_reached_at_it():
    """Chance 0.5: the bar 0.6; a point at 0.6 has not left chance but has reached 0.5; 0.9 is reached at 0.9."""
    points = [(100, 0.6), (200, 0.61), (300, 0.9)]
    assert first_crossing(points, "sgn_test", "chance", floor=0.5) == 200
    assert first_crossing(points, "sgn_test", "0.5", floor=0.5) == 100
    assert first_crossing(points, "sgn_test", "0.9", floor=0.5) == 300


def test_the_curves_keep_a_resumed_points_last_value_in_frame_order(tmp_path):
    path = tmp_path / "metrics.csv"
    lines = ["200,eval/sgn_test,0.5", "100,eval/sgn_test,0.2", "200,eval/sgn_test,0.6", "100,train/loss,3.0"]
    path.write_text("\n".join(["step,key,value", *lines, "100,eval/eqa_train,0.4"]) + "\n")
    assert curves(read_curve(tmp_path, CURVE_KEYS)) == {"sgn_test": [(100, 0.2), (200, 0.6)], "eqa_train": [(100, 0.4)]}
    assert curves(read_curve(tmp_path / "absent", CURVE_KEYS)) == {}


def test_a_runs_crossings_its_last_evaluation_and_its_largest_gap(tmp_path):
    """SGN test 0.5, 0.6, 0.95 at 99,328, 199,680 and 299,008 frames (gaps 100,352 and 99,328); chance 0.5 (bar
    0.6): it leaves chance at 299,008 and reaches 0.5 at 99,328, 0.9 at 299,008. EQA never evaluated: absent."""
    points = [(99_328, 0.5), (199_680, 0.6), (299_008, 0.95)]
    write_points(tmp_path, W_O_SA, [f"{s},eval/sgn_test,{v}" for s, v in points] + ["50000,eval/sgn_train,0.1"])
    chance = Chance({(W_O_SA.difficulty, "sgn_test"): 0.5})
    eff = run_efficiency(W_O_SA, W_O_SA.run_name(PROFILE), tmp_path, chance)
    assert (eff.run, eff.row, eff.difficulty, eff.aux, eff.seed) == (
        W_O_SA.run_name(PROFILE),
        "w/o SA",
        "easy",
        True,
        0,
    )
    assert eff.found and (eff.last, eff.every) == (299_008, 100_352)
    assert eff.crossings == {
        "sgn_test": {"chance": 299_008, "0.5": 99_328, "0.9": 299_008},
        "sgn_train": {"chance": None, "0.5": None, "0.9": None},
    }
    # the task's blind ceiling by default: Easy SGN 0.2 (the goal's slot uniform over 5), its bar 0.3: left at 99,328
    assert run_efficiency(W_O_SA, W_O_SA.run_name(PROFILE), tmp_path).crossings["sgn_test"]["chance"] == 99_328
    gone = run_efficiency(W_O_SA, W_O_SA.run_name(PROFILE), tmp_path / "nowhere")
    assert (gone.found, gone.crossings, gone.last, gone.every) == (False, {}, 0, 0)
    one = tmp_path / "one"
    write_points(one, W_O_SA, ["1000,eval/sgn_test,0.5"])
    assert run_efficiency(W_O_SA, W_O_SA.run_name(PROFILE), one).every == 0
    assert table_efficiency(plan_report("table3", PROFILE, run_root=tmp_path), [eff.run], chance) == [eff]


def test_the_section_lists_each_run_and_its_cadence(tmp_path):
    points = [(99_328, 0.5), (199_680, 0.6), (299_008, 0.95)]
    write_points(tmp_path, W_O_SA, [f"{s},eval/sgn_test,{v}" for s, v in points])
    eff = run_efficiency(W_O_SA, W_O_SA.run_name(PROFILE), tmp_path, Chance({("easy", "sgn_test"): 0.5}))
    gone = run_efficiency(W_O_SA, W_O_SA.run_name(PROFILE), tmp_path / "nowhere")
    text = markdown([eff, gone], ("sgn_test", "eqa_test"))
    lines = text.splitlines()
    assert lines[:2] == ["### Sample efficiency", ""] and text.endswith(" |\n")
    assert (
        "first leaves chance (above chance + 0.10; chance is the best a model that sees no frame can score, the best "
        "fixed answer per question (EQA) and the best fixed object slot per instruction (SGN), enumerated from the "
        "episode generator (emml/envs/ceiling.py): " in text
    )
    assert "Easy: SGN test 0.20, EQA test 0.56, SGN train 0.20, EQA train 0.44)" in text  # the ceiling by default
    assert "Evaluations at most 100,352 frames apart: a crossing is known to that resolution." in text
    assert lines[-4:] == [
        "| Run | Setting | seed | SGN test |",  # EQA test: no run evaluated it
        "|:--|:--|--:|:--|",
        "| w/o SA | Easy · Aux | 0 | 0.30M / 0.10M / 0.30M |",
        "| w/o SA | Easy · Aux | 0 | no metrics.csv here |",
    ]
    assert markdown([]) == ""
    assert "at most — frames apart" in markdown([gone])
    eqa = run_efficiency(W_O_SA, W_O_SA.run_name(PROFILE), tmp_path)
    eqa.crossings["eqa_test"] = {"chance": None, "0.5": None, "0.9": None}
    del eqa.crossings["sgn_test"]
    assert markdown([eff, eqa], ("sgn_test", "eqa_test")).splitlines()[-1] == (
        "| w/o SA | Easy · Aux | 0 | — | >0.30M / >0.30M / >0.30M |"
    )


def test_the_section_states_the_chance_it_reads_and_each_cadence(tmp_path):
    """Two runs evaluated 100,352 and 50,000 frames apart, the No Aux one in Easy; chance given: its source and
    only the runs' difficulties are stated."""
    no_aux = next(s for s in load_table("table3").runs([0]) if s.row == "w/o SA" and not s.aux)
    write_points(tmp_path, W_O_SA, [f"{s},eval/sgn_test,0.9" for s in (99_328, 199_680)])
    write_points(tmp_path, no_aux, [f"{s},eval/sgn_test,0.9" for s in (50_000, 100_000)])
    chance = Chance({("easy", "sgn_test"): 0.25}, "a fixture's blind runs")
    runs = [run_efficiency(s, s.run_name(PROFILE), tmp_path, chance) for s in (W_O_SA, no_aux)]
    runs[1].crossings["sgn_x"] = {"chance": None, "0.5": None, "0.9": None}  # a metric without a label
    lines = markdown(runs, ("sgn_test", "sgn_x"), chance).splitlines()
    assert lines[2] == (
        "Frames at which each run's greedy accuracy (its periodic evaluation in `metrics.csv`) first leaves chance "
        "(above chance + 0.10; chance is the best a model that sees no frame can score, a fixture's blind runs: Easy: "
        "SGN test 0.25, "
        "EQA test 0.33 (uniform), SGN train 0.20 (uniform), EQA train 0.33 (uniform)), then reaches 0.5 and 0.9, as "
        "'leaves chance / 0.5 / 0.9'; >F: not by its last evaluation at F frames. Evaluations at most 50,000, 100,352 "
        "frames apart: a crossing is known to that resolution."
    )
    assert lines[3] == "" and lines[4] == "| Run | Setting | seed | SGN test | sgn_x |"
    assert lines[-2:] == [
        "| w/o SA | Easy · Aux | 0 | 0.10M / 0.10M / 0.10M | — |",
        "| w/o SA | Easy · No Aux | 0 | 0.05M / 0.05M / 0.05M | >0.10M / >0.10M / >0.10M |",
    ]


def test_a_tables_crossings_read_the_tasks_blind_ceiling_by_default(tmp_path, monkeypatch):
    """No chance given: the task's ceiling (emml/report/chance.py `task_ceiling`), whatever the profile's results."""
    import emml.report.chance

    monkeypatch.setattr(emml.report.chance, "task_ceiling", lambda: Chance({("easy", "sgn_test"): 0.5}))
    points = [(99_328, 0.5), (199_680, 0.6), (299_008, 0.95)]
    write_points(tmp_path, W_O_SA, [f"{s},eval/sgn_test,{v}" for s, v in points])
    plan = plan_report("table3", PROFILE, results_root=tmp_path / "results", run_root=tmp_path)
    (eff,) = table_efficiency(plan, [W_O_SA.run_name(PROFILE)])
    assert eff.crossings["sgn_test"]["chance"] == 299_008  # above 0.6, not the uniform 0.3


def test_a_runs_eqa_leaves_chance_above_the_enumerated_ceiling_not_the_uniform_third(tmp_path):
    """Easy EQA test: the best fixed answer per question scores 0.5625 (tests/envs/test_ceiling.py), the bar 0.6625;
    a curve at 0.45, 0.6, 0.7 leaves chance at its third point (the uniform 1/3 would have it at its first)."""
    points = [(100_000, 0.45), (200_000, 0.6), (300_000, 0.7)]
    write_points(tmp_path, W_O_SA, [f"{s},eval/eqa_test,{v}" for s, v in points])
    eff = run_efficiency(W_O_SA, W_O_SA.run_name(PROFILE), tmp_path)
    assert eff.crossings["eqa_test"] == {"chance": 300_000, "0.5": 200_000, "0.9": None}
