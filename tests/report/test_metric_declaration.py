"""The pages follow the metric declaration (issue 64 item 1): change a metric's label, colour or chance floor in
emml/eval/metrics.py and every reader prints the new one."""

import dataclasses

import pytest

from emml.eval import metrics
from emml.experiments.claims.evidence import Chance
from emml.experiments.claims.kinds import metric_text
from emml.report import cells, curves, efficiency
from emml.report.chance import chance_text


@pytest.fixture
def renamed(monkeypatch):
    """Every metric relabelled 'Label of <name>', its curve labelled 'Curve of <name>'."""
    for name, m in list(metrics.BY_NAME.items()):
        new = dataclasses.replace(m, label=f"Label of {name}", curve_label=f"Curve of {name}" if m.curve_label else "")
        monkeypatch.setitem(metrics.BY_NAME, name, new)
    return metrics.BY_NAME


def test_every_label_a_page_prints_is_the_declared_one(renamed):
    for name in metrics.BY_NAME:
        assert cells.level_label("metric", name) == f"Label of {name}"
        assert metric_text(name) == f"Label of {name}"
        expect = f"Curve of {name}" if name in metrics.TRANSFER_METRICS else f"Label of {name}"
        assert curves.curve_key(name) == (renamed[name].key, expect)
    text = chance_text(Chance(), ("easy",))
    for name in metrics.CHANCE_COLUMNS:
        assert f"Label of {name} " in text, text
    run = efficiency.RunEfficiency("r", "Row", "easy", True, 0, {"sgn_test": dict.fromkeys(efficiency.MARKS)}, 10)
    page = efficiency.markdown([run])
    assert "| Run | Setting | seed | Label of sgn_test |" in page, page


def test_the_chance_floor_and_column_are_the_declared_ones(monkeypatch):
    sgn = metrics.BY_NAME["sgn_test"]
    monkeypatch.setitem(metrics.BY_NAME, "sgn_test", dataclasses.replace(sgn, uniform=0.125))
    assert Chance().of("sgn_test", "easy") == 0.125
    assert Chance().of("sgn_train", "easy") == 0.2
    measured = Chance({("easy", "sgn_test"): 0.5})
    assert measured.of("sgn_transfer:go to the torch", "easy") == 0.5  # a transfer instruction: the test column's
    monkeypatch.setitem(
        metrics.BY_NAME, "sgn_transfer", dataclasses.replace(metrics.BY_NAME["sgn_transfer"], chance="sgn_train")
    )
    assert measured.of("sgn_transfer:go to the torch", "easy") == 0.2 and not measured.measured("sgn_transfer", "easy")


def test_a_runs_curves_are_drawn_in_the_declared_colours():
    drawn = {key: (label, colour) for key, label, colour, _ in curves.SERIES}
    for m in metrics.DECLARED:
        if m.periodic:
            assert drawn[m.key] == (f"{m.label}, greedy eval", m.colour)
    assert drawn["train/success_sgn"][1] == metrics.train_of("sgn").colour


def test_a_claims_colour_is_its_tasks_declared_one():
    from emml.report.claims_figure import TASK_COLOURS

    for task in metrics.TASKS:
        assert TASK_COLOURS[task] == metrics.train_of(task).colour
