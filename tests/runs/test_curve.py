"""A run's curve read by its one reader (emml/runs/curve.py), on a FIXTURE: a private MLflow store and run dirs in
tmp_path (never runs/)."""

from emml.runs.curve import DAMAGED, MIRROR, STORE, read_curve
from emml.runs.tracking import Tracker


def logged(points: dict[int, float], key: str = "eval/sgn_test") -> str:
    """FIXTURE: a run in the test's store holding ``points`` of ``key``; its run id."""
    tracker = Tracker()
    run_id = tracker.start("table3", "a-run")
    for step, value in points.items():
        tracker.log_metrics({key: value}, step=step)
    tracker.finish()
    return run_id


def mirror(folder, lines: list[str]):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "metrics.csv").write_text("step,key,value\n" + "".join(f"{line}\n" for line in lines))
    return folder


def test_the_run_dirs_metrics_csv_comes_before_the_store_whatever_the_store_holds(tracking, tmp_path):
    run_id = logged({100: 0.9, 200: 0.9, 300: 0.9})
    folder = mirror(tmp_path / "run", ["100,eval/sgn_test,0.2", "200,eval/sgn_test,0.4", "200,eval/sgn_test,0.5"])
    curve = read_curve(folder, ["eval/sgn_test", "eval/eqa_test"], run_id)
    assert curve.source == MIRROR and curve.of("eval/sgn_test") == [(100, 0.2), (200, 0.5)]  # the last value kept
    assert curve.of("eval/eqa_test") == [] and set(curve.points) == {"eval/sgn_test"}


def test_without_a_metrics_csv_the_store_gives_the_curve_and_without_either_a_reason(tracking, tmp_path):
    run_id = logged({100: 0.3, 200: 0.6})
    curve = read_curve(tmp_path / "elsewhere", ["eval/sgn_test"], run_id)
    assert curve.source == STORE and curve.of("eval/sgn_test") == [(100, 0.3), (200, 0.6)]
    assert read_curve(tmp_path / "elsewhere", None, run_id).of("eval/sgn_test") == [(100, 0.3), (200, 0.6)]
    header_only = mirror(tmp_path / "fresh", [])  # a run dir whose mirror holds no point yet: the store's
    assert read_curve(header_only, ["eval/sgn_test"], run_id).source == STORE
    gone = read_curve(tmp_path / "elsewhere", ["eval/sgn_test"], "not-in-this-store")
    assert not gone.found and gone.source == "" and "no MLflow run not-in-this-store" in gone.reason
    assert "no MLflow run id" in read_curve(tmp_path / "elsewhere", ["eval/sgn_test"], float("nan")).reason
    other = read_curve(tmp_path / "elsewhere", ["eval/eqa_test"], run_id)  # the run is there, not that key
    assert other.source == STORE and not other.found and "eval/eqa_test" in other.reason


def test_a_damaged_metrics_csv_is_the_runs_reason_not_a_turn_to_the_store(tracking, tmp_path, capsys):
    run_id = logged({100: 0.3})
    folder = mirror(tmp_path / "run", ["100,eval/sgn_test,0.2", "garbage"])
    curve = read_curve(folder, ["eval/sgn_test"], run_id)
    assert curve.damaged and curve.reason == DAMAGED and not curve.found
    assert "line 3" in capsys.readouterr().err  # the note names the line


def test_a_file_is_read_again_when_it_changes(tmp_path):
    folder = mirror(tmp_path / "run", ["100,eval/sgn_test,0.2"])
    assert read_curve(folder, ["eval/sgn_test"]).of("eval/sgn_test") == [(100, 0.2)]
    mirror(folder, ["100,eval/sgn_test,0.25", "200,eval/sgn_test,0.5"])
    assert read_curve(folder, ["eval/sgn_test"]).of("eval/sgn_test") == [(100, 0.25), (200, 0.5)]
    mirror(folder, ["100,train/loss,1.0"])  # points, none of the key asked: still the mirror's (no store asked)
    curve = read_curve(folder, ["eval/sgn_test"], "any-id")
    assert curve.source == MIRROR and not curve.found and "eval/sgn_test" in curve.reason
