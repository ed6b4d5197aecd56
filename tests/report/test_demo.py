"""`make demo`'s report (emml/report/demo.py) written on made-up inputs (issue 66: it ran in no test): a run's curves
and diagnostics logged by hand into a private MLflow store, its final accuracies given; the report's tables have as
many cells in each row as their header has columns, with the numbers logged, and its figure plots the logged curve.
These numbers are made up for the test, never results."""

from __future__ import annotations

from types import SimpleNamespace

import mlflow
import pytest
from matplotlib.figure import Figure
from PIL import Image

from emml.config.profiles import profile_config
from emml.eval.diagnose import SCALARS
from emml.report.demo import write_demo_report
from emml.runs.naming import run_name

STEPS = (20_480, 40_960, 81_920)
SGN_TRAIN = {20_480: 0.21, 40_960: 0.48, 81_920: 0.83}
SGN_TEST = {20_480: 0.18, 40_960: 0.4, 81_920: 0.66}
DIAG = {k: {s: 0.1 * (i + 1) + 0.01 * j for j, s in enumerate(STEPS)} for i, k in enumerate(SCALARS)}


def _table(lines: list[str], first: str) -> list[list[str]]:
    """The markdown table whose header line starts with ``first``: its lines split into cells, header first."""
    start = next(i for i, line in enumerate(lines) if line.startswith(first))
    rows = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip().strip("|").split("|")])
    return rows


@pytest.fixture
def demo_run(tracking, tmp_path):
    """A finished demo run as `emml demo` hands it to the report: its config, and an MLflow run holding its greedy
    evaluations and diagnostics at three evaluations and a training-episode curve."""
    cfg = profile_config("demo", "easy", {"env.tasks": "sgn", "run_root": tracking["run_root"]}, aux=True, seed=0)
    client = mlflow.MlflowClient(tracking["uri"])
    run_id = client.create_run(client.create_experiment("demo")).info.run_id
    for s in STEPS:
        client.log_metric(run_id, "eval/sgn_train", SGN_TRAIN[s], step=s)
        client.log_metric(run_id, "eval/sgn_test", SGN_TEST[s], step=s)
        client.log_metric(run_id, "train/success_sgn", SGN_TRAIN[s] - 0.05, step=s)
        for k in SCALARS:
            client.log_metric(run_id, f"diag/{k}", DIAG[k][s], step=s)
    client.log_metric(run_id, "eval/sgn_train", 0.5, step=STEPS[-1] + 1)  # a step with no diagnostics: dashes
    client.set_terminated(run_id)
    result = SimpleNamespace(
        run_id=run_id,
        frames=163_840,
        metrics={"sgn_train": 0.875, "sgn_test": 0.6125},
        run_dir=tmp_path / "runs" / "demo" / "dual_attention-easy-aux-s0-demo",
    )
    return cfg, result


def test_the_demo_report_tables_agree_with_their_headers_and_hold_the_logged_numbers(demo_run, tmp_path):
    cfg, result = demo_run
    md, png = write_demo_report(cfg, result, tmp_path / "reports")
    lines = md.read_text().splitlines()
    assert lines[0] == f"# Demo run: {run_name(cfg)}"
    assert "profile **demo** (163,840 frames, 4 actors × 64 steps per update, input 60×108" in md.read_text()

    accuracy = _table(lines, "| task |")
    assert accuracy[0] == ["task", "train", "test"]
    assert accuracy[2:] == [["SGN", "0.88", "0.61"]]  # SGN only: no EQA row
    assert all(len(row) == len(accuracy[0]) for row in accuracy)

    diag = _table(lines, "| frames |")
    head, rule, body = diag[0], diag[1], diag[2:]
    assert len(rule) == len(head) and all(len(row) == len(head) for row in body), (head, body)
    assert head[:3] == ["frames", "SGN train", "SGN test"] and len(head) == 3 + len(SCALARS)
    assert "x_I spatial std" in head and "detector AP" in head
    assert [row[0] for row in body] == [f"{s:,}" for s in (*STEPS, STEPS[-1] + 1)]
    for row, s in zip(body, STEPS):
        assert row[1:3] == [f"{SGN_TRAIN[s]:.2f}", f"{SGN_TEST[s]:.2f}"]
        for k, cell in zip(SCALARS, row[3:]):
            assert float(cell) == pytest.approx(DIAG[k][s], abs=0.0005 if k == "x_image_spatial_std" else 0.005)
    assert body[-1][1:] == ["0.50", *["—"] * (len(head) - 2)]
    assert f"![training curve]({png.name})" in lines and f"MLflow run `{result.run_id}`" in md.read_text()


def test_the_demo_figure_plots_the_logged_curves(demo_run, tmp_path, monkeypatch):
    """The figure's content, read from the matplotlib Figure as it is saved: the logged series at their frames, the
    axes labelled, the title naming the run's setting."""
    saved: list[Figure] = []
    original = Figure.savefig

    def keep(fig, *args, **kwargs):
        saved.append(fig)
        return original(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    cfg, result = demo_run
    _, png = write_demo_report(cfg, result, tmp_path / "reports")
    (fig,) = saved
    (ax,) = fig.axes
    series = {line.get_label(): line for line in ax.get_lines()}
    greedy = series["SGN train, greedy eval"]
    assert list(greedy.get_xdata()) == [*STEPS, STEPS[-1] + 1]
    assert list(greedy.get_ydata()) == pytest.approx([*SGN_TRAIN.values(), 0.5])
    assert list(series["SGN test, greedy eval"].get_ydata()) == pytest.approx(list(SGN_TEST.values()))
    assert list(series["SGN, training episodes"].get_ydata()) == pytest.approx([v - 0.05 for v in SGN_TRAIN.values()])
    assert not any("EQA" in label for label in series)  # nothing logged for EQA: no EQA series
    assert ax.get_xlabel() == "M frames" and ax.get_ylabel() == "accuracy"  # frames in millions (the reports' axis)
    assert "dual_attention, Doom easy, SGN only, aux=True: profile demo, 163,840 frames" in ax.get_title()
    with Image.open(png) as img:
        assert img.format == "PNG"
