"""`emml import-runs` stores fewer points where they add nothing: the keys the report's pages read (eval/*, diag/*,
final/*) whole, each per-update key thinned to `PER_KEY` real points, the whole metrics.csv as the run's artifact;
and names a run dir outside the checkout without '..' (emml/runs/thinning.py, emml/runs/portable.py)."""

import io
import json
import shutil
import sys
from pathlib import Path

import pytest

from emml.config.paths import checkout_root
from emml.runs import store
from emml.runs.import_runs import IMPORTED_FROM, import_run_dir, import_runs, read_points, relative
from emml.runs.portable import OUTSIDE, named
from emml.runs.thinning import PER_KEY, evenly, kept_whole, stored_count, thinned
from emml.runs.tracking import Tracker
from tests.runs.test_import_runs import CONFIG, write_run


@pytest.fixture(autouse=True)
def _store(tmp_path, monkeypatch):
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path / 'store' / 'mlflow.db'}")
    monkeypatch.setenv("MLFLOW_DISABLE_TELEMETRY", "true")


def test_evenly_keeps_the_first_the_last_and_as_many_as_asked():
    steps = list(range(0, 1000 * 64, 64))
    kept = evenly(steps, 10)
    assert len(kept) == 10 and kept[0] == 0 and kept[-1] == steps[-1]
    gaps = {b - a for a, b in zip(kept, kept[1:])}
    assert max(gaps) - min(gaps) <= 64  # evenly spaced, to an update
    assert evenly(steps[:10], 10) == steps[:10] and evenly(steps[:3], 10) == steps[:3]
    with pytest.raises(ValueError, match="keep: at least 2"):
        evenly(steps, 1)


def test_thinned_keeps_the_pages_keys_whole_and_thins_the_per_update_ones():
    n = 3 * PER_KEY  # more points than PER_KEY in every key: whole or thinned by its name, not its count
    points = [(64 * i, key, i / n) for i in range(1, n + 1) for key in ("train/loss", "eval/sgn_test", "diag/ap")]
    points += [(64 * n, "final/sgn_test", 0.5), (64, "perf/eval_s", 3.0), (64, "train/loss", 9.0)]  # a re-logged step
    out = thinned(points)
    by_key = {}
    for step, key, value in out:
        by_key.setdefault(key, []).append((step, value))
    assert [len(by_key[k]) for k in ("eval/sgn_test", "diag/ap", "final/sgn_test")] == [n, n, 1]
    assert len(by_key["perf/eval_s"]) == 1  # fewer than PER_KEY: whole
    loss = by_key["train/loss"]
    assert len(loss) == PER_KEY and loss[0] == (64, 9.0) and loss[-1] == (64 * n, 1.0)  # the last value of a step
    assert all(v == s / 64 / n for s, v in loss[1:])  # values the run logged, at their own steps
    assert [k for _, k, _ in out] == sorted(k for _, k, _ in out)
    assert kept_whole("eval/eqa_test") and kept_whole("diag/gate_dead") and not kept_whole("charts/fps")


LARGEST = max(
    (p for p in (checkout_root() / "runs").glob("*/*/metrics.csv") if (p.parent / "results.json").is_file()),
    key=lambda p: p.stat().st_size,
    default=None,
)
"""The committed run dir with the longest curve (a Table 2 hard run: ~88k points)."""


@pytest.mark.skipif(LARGEST is None, reason="no committed run dir")
def test_a_committed_run_keeps_every_curve_a_page_reads_and_its_whole_curve_as_an_artifact(tmp_path):
    run = tmp_path / "runs" / LARGEST.parent.parent.name / LARGEST.parent.name
    run.mkdir(parents=True)
    for name in ("results.json", "metrics.csv"):
        shutil.copy(LARGEST.parent / name, run / name)
    mirror = read_points(run / "metrics.csv")
    keys = sorted({k for _, k, _ in mirror})
    whole = [k for k in keys if k.startswith(("eval/", "diag/"))]
    per_update = [k for k in keys if sum(1 for _, kk, _ in mirror if kk == k) > PER_KEY]
    assert {"eval/sgn_test", "eval/eqa_test", "diag/detector_ap"} <= set(whole) and "train/success_sgn" in per_update
    result = import_run_dir(run)
    assert result.outcome == "imported" and result.points < result.read / 5, result.line()
    rid = result.mlflow_run_id
    for key in whole:  # the report's curves (eval/*: curves.py, efficiency.py), the claims' diag/*: every point
        expected = sorted({st: v for st, k, v in mirror if k == key}.items())
        assert store.metric_history(rid, key) == expected, key
    for key in per_update:
        history = store.metric_history(rid, key)
        steps = sorted({st for st, k, _ in mirror if k == key})
        assert len(history) == PER_KEY and (history[0][0], history[-1][0]) == (steps[0], steps[-1]), key
    final = store.client().get_run(rid).data.metrics
    assert {k for k in final if k.startswith("final/")} == {f"final/{k}" for k in _score(run)}
    artifact = Path(store.client().download_artifacts(rid, "metrics.csv", str(tmp_path / "dl")))
    assert artifact.read_bytes() == (run / "metrics.csv").read_bytes()  # the whole curve, one click away


def _score(run: Path) -> list[str]:
    """The run's final scores (results.json "metrics") that have a value."""
    score = json.loads((run / "results.json").read_text()).get("metrics") or {}
    return [k for k, v in score.items() if v is not None]


def test_a_run_dir_outside_the_checkout_is_named_from_its_run_root(tmp_path):
    """A run trained or imported with its run dir outside the checkout: its checkpoint and run dir tags read from the
    name its run_root param has, never '..' nor a folder of the machine."""
    root = tmp_path / "ext-runs"
    trained = write_run(tmp_path, "outside", "r-s3", "f" * 32, config={**CONFIG, "run_root": str(root)})
    run = root / "outside" / "r-s3"
    run.parent.mkdir(parents=True)
    trained.rename(run)
    (run / "checkpoint.pt").write_bytes(b"")
    ext = f"ext-runs{OUTSIDE}"
    assert relative(run) == f"{ext}/outside/r-s3"
    result = import_run_dir(run)
    got = store.client().get_run(result.mlflow_run_id).data
    assert got.tags["checkpoint"] == f"{ext}/outside/r-s3/checkpoint.pt" and got.tags[IMPORTED_FROM] == relative(run)
    assert got.params["run_root"] == ext
    values = {**got.tags, **got.params}
    assert not [f"{k}={v}" for k, v in values.items() if v.startswith(("/", "..")) or "/../" in v or str(tmp_path) in v]

    tracker = Tracker()  # the trainer's tags: its checkpoint's absolute path under its run root, named the same
    cfg = {**CONFIG, "run_root": str(root), "init_from": str(run / "checkpoint.pt")}
    rid = tracker.start("outside", "trained", {"checkpoint": str(run / "checkpoint.pt")}, cfg)
    tracker.finish()
    data = store.client().get_run(rid).data
    assert data.tags["checkpoint"] == data.params["init_from"] == f"{ext}/outside/r-s3/checkpoint.pt"
    assert data.params["run_root"] == ext


def test_named_never_writes_dotdot_and_is_its_own_fixed_point(tmp_path):
    here = checkout_root()
    roots = {str(tmp_path / "ext"): f"ext{OUTSIDE}"}
    cases = {
        str(here / "runs" / "table2" / "x"): "runs/table2/x",
        str(tmp_path / "ext" / "t" / "x" / "checkpoint.pt"): f"ext{OUTSIDE}/t/x/checkpoint.pt",
        str(tmp_path / "ext"): f"ext{OUTSIDE}",
        "/work/main/runs/table2/x/checkpoint.pt": "runs/table2/x/checkpoint.pt",  # another machine's checkout
        "/srv/data/init.pt": f"init.pt{OUTSIDE}",
        f"('{here}/a', '/tmp/b')": f"('a', 'b{OUTSIDE}')",
        "sqlite:///x/mlflow.db": "sqlite:///x/mlflow.db",
        "train/success_sgn": "train/success_sgn",
    }
    for value, expected in cases.items():
        assert named(value, roots) == expected, value
        assert named(expected, roots) == expected, expected  # a named value stays as it is


@pytest.mark.skipif(LARGEST is None, reason="no committed run dir")
def test_a_run_dirs_share_of_the_progress_bar_is_the_points_it_stores():
    from emml.runs.import_runs import BYTES_PER_POINT, RUN_POINTS, work

    assert stored_count(LARGEST) == len(thinned(read_points(LARGEST)))  # counted without reading the values
    read = LARGEST.stat().st_size // BYTES_PER_POINT
    assert work(LARGEST.parent) == stored_count(LARGEST) + read + RUN_POINTS
    assert stored_count(LARGEST.parent / "absent.csv") == 0


class Terminal(io.StringIO):
    """stderr as a terminal: the progress bar is drawn."""

    def isatty(self) -> bool:
        return True


def test_the_progress_bar_ends_full_when_run_dirs_are_skipped(tmp_path, monkeypatch):
    """The bar counts the points to store: a run dir already in the store takes its share off the total, so that the
    ETA is the imports' left and the bar ends at 100%."""
    first = write_run(tmp_path, "bar", "first", "1" * 32)
    write_run(tmp_path, "bar", "second", "2" * 32)
    import_run_dir(first)
    shown = Terminal()
    monkeypatch.setattr(sys, "stderr", shown)
    results = import_runs([tmp_path / "runs"], progress=True)
    assert [r.outcome for r in results] == ["skipped", "imported"]
    last = shown.getvalue().replace("\r", "\n").strip().splitlines()[-1]
    assert last.startswith("100%") and " pt" in last, last
