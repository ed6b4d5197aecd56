"""Sample efficiency and the speed and diagnostic claims (emml/report/efficiency.py, emml/report/claims.py, issue 49)
on a FIXTURE: made-up results rows and metrics.csv files in tmp_path (never results)."""

from emml.config.profiles import profile_seeds
from emml.experiments.tables import load_table
from emml.report.claims import BUDGET, CONTRADICTED, INCONCLUSIVE, SUPPORTED, UNTESTABLE, decide
from emml.report.efficiency import first_crossing, markdown, run_efficiency
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
    eff = run_efficiency(spec, PROFILE, runs)
    at = eff.last * 3 // 10
    assert eff.crossings["sgn_test"] == {"chance": at, "0.5": at, "0.9": at}
    text = markdown([eff, run_efficiency(spec, PROFILE, tmp_path / "nowhere")])
    assert f"| w/o SA | Easy · Aux | 0 | {at / 1e6:.2f}M / {at / 1e6:.2f}M / {at / 1e6:.2f}M |" in text
    assert "no metrics.csv here" in text
    mirror = runs / spec.table / spec.run_name(PROFILE) / "metrics.csv"  # issue 65: a garbage line costs this run
    mirror.write_text(mirror.read_text().replace("\n", "\ngarbage\n", 2))
    damaged = run_efficiency(spec, PROFILE, runs)
    assert not damaged.found and damaged.damaged and "| metrics.csv damaged |" in markdown([eff, damaged])
