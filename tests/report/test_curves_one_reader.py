"""The table page and the claims page read a run's curve through one reader (emml/runs/curve.py), on a FIXTURE: a run
whose MLflow store (a private one) and whose run dir's metrics.csv (in tmp_path) hold different points."""

from emml.experiments.claims.evidence import Score
from emml.experiments.tables import load_table
from emml.report.cells import table_results
from emml.report.claims import gather
from emml.report.curves import table_curves
from emml.report.efficiency import first_crossing, table_efficiency
from emml.report.plan import plan_report
from emml.runs.tracking import Tracker
from tests.report.test_claims_page import CLAIMS, edit
from tests.report.test_efficiency import write_curves
from tests.report.test_tables import PROFILE, fake_results

W_O_SA = next(s for s in load_table("table3").runs([0]) if s.row == "w/o SA" and s.difficulty == "easy" and s.aux)
"""The run both pages read: Table 3's w/o SA, Easy · Aux, seed 0 (a row of the claim 'ablation-sa-ga1')."""
KEY = "eval/sgn_test"


def both_pages(results, runs) -> tuple[list, dict | None, list]:
    """The run's SGN test curve as the table page's figure holds it (its line's points, fetched before it draws) and
    as the claims page reads it (the score's curve a reversal is weighed on), and the table page's sample-efficiency
    crossings of it."""
    plan = plan_report("table3", PROFILE, results, runs)
    name = W_O_SA.run_name(PROFILE)
    figure = table_curves(plan, table_results(plan.table, plan.profile, plan.results_root))
    (line,) = [ln for ln in figure.panels[("sgn_test", "easy", True)] if ln.row == "w/o SA"]
    seeds = {tuple(zip(x.tolist(), y.tolist())) for x, y in line.curves}
    assert tuple(figure.read[name].of(KEY)) in seeds  # the line the figure draws is the curve it fetched
    ev = gather(CLAIMS["ablation-sa-ga1"], plan)
    (score,) = [s for s in ev.scores[("w/o SA", "easy", True, "sgn_test")] if s.run == name]
    assert isinstance(score, Score) and score.metric == "sgn_test"
    (eff,) = table_efficiency(plan, [name])
    return figure.read[name].of(KEY), ev.curves(score), eff.crossings.get("sgn_test")


def test_the_table_page_and_the_claims_page_read_the_same_curve_when_mlflow_and_metrics_csv_differ(tracking, tmp_path):
    results, runs = tmp_path / "results", tmp_path / "runs"
    fake_results("table3", results, value=lambda spec: 0.9)
    fake_results("table2", results, value=lambda spec: 0.9)  # Table 3's DA Multi-Task is Table 2's Dual-Attention
    write_curves(runs, "table3", lambda s: 0.3)  # every run dir's metrics.csv: 0.2, then 0.95 from 0.3 of its frames
    write_curves(runs, "table2", lambda s: 0.3)
    name = W_O_SA.run_name(PROFILE)
    mirror = [(s, v) for s, k, v in _points(runs / W_O_SA.table / name / "metrics.csv") if k == KEY]
    tracker = Tracker()  # its MLflow run holds other points: 0.5 at other frames
    run_id = tracker.start("table3", name)
    stored = [(1000 * i, 0.5) for i in range(1, 4)]
    for step, value in stored:
        tracker.log_metrics({KEY: value}, step=step)
    tracker.finish()
    edit(results, "table3", name, run_id=run_id)
    assert mirror and dict(mirror) != dict(stored)

    table_page, claims_page, crossings = both_pages(results, runs)
    assert table_page == mirror and claims_page == dict(mirror)  # both the run dir's, the order of emml/runs/curve.py
    assert crossings["chance"] == first_crossing(table_page, "sgn_test", "chance", 0.2) is not None

    (runs / W_O_SA.table / name / "metrics.csv").unlink()  # its run dir's curve not here: both read the store
    table_page, claims_page, crossings = both_pages(results, runs)
    assert table_page == stored and claims_page == dict(stored)
    assert crossings is not None  # the efficiency section reads it too (0.5 leaves chance 0.2 at its first point)


def _points(path) -> list[tuple[int, str, float]]:
    from emml.runs.records import read_points

    return read_points(path)
