"""A metric is a declaration: emml/eval/metrics.py names each metric once, beside the evaluation that writes the
values; no reader spells a metric's curve key or label itself, and the writers spell no metric's name."""

import ast
from pathlib import Path

import pytest

import emml
from emml.eval import metrics
from emml.eval.metrics import BY_NAME, DECLARED, metric

HOME = Path(emml.__file__).parent
DECLARATION = HOME / "eval" / "metrics.py"
WRITERS = (HOME / "eval" / "evaluate.py", HOME / "eval" / "transfer.py")
"""The modules that write the values: the greedy evaluation, Table 4's transfer."""


def test_each_metric_is_declared_once_with_a_known_task_split_and_chance():
    assert len(BY_NAME) == len(DECLARED)
    for m in DECLARED:
        assert m.task in metrics.TASKS and m.split in metrics.METRIC_SPLITS, m
        assert m.key.startswith("eval/"), m
        assert m.chance in BY_NAME and BY_NAME[m.chance].task == m.task, m
        assert 0 < m.uniform < 1 and m.colour, m
    assert metrics.METRICS == ("sgn_test", "eqa_test", "sgn_train", "eqa_train")
    assert metrics.TRANSFER_METRICS == ("sgn_transfer",)
    assert metrics.TRAIN_COLUMNS == ("sgn_train", "eqa_train")
    assert metrics.CURVE_METRICS == metrics.METRICS
    assert metrics.CHANCE_COLUMNS == metrics.METRICS
    assert metric("sgn_transfer:go to the red torch") is BY_NAME["sgn_transfer"]
    assert [metrics.train_of(t).name for t in metrics.TASKS] == ["sgn_train", "eqa_train"]


def _literals(path: Path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            yield node.lineno, node.value


def test_no_reader_spells_a_metric_key_or_label():
    """A reader that writes 'eval/sgn_test' or 'SGN test' itself would not follow the declaration (the readers'
    behaviour under a changed declaration: tests/report/test_metric_declaration.py)."""
    spelled = {m.key for m in DECLARED} | {m.label for m in DECLARED if m.split != metrics.TRANSFER}
    spelled |= {m.curve for m in DECLARED}
    found = [
        f"{path.relative_to(HOME.parent)}:{line}: {text!r}"
        for path in sorted(HOME.rglob("*.py"))
        if path != DECLARATION
        for line, text in _literals(path)
        if text in spelled
    ]
    assert not found, "read these from emml/eval/metrics.py:\n" + "\n".join(found)


def test_a_transfer_metrics_column_is_the_one_the_transfer_writes():
    from emml.eval.transfer import METRIC, metric_column

    assert METRIC == metrics.TRANSFER_METRIC.name and METRIC in metrics.TRANSFER_METRICS
    assert BY_NAME[METRIC].column("go to the torch") == metric_column("go to the torch") == f"{METRIC}:go to the torch"


def test_the_evaluation_writes_one_declared_metric_per_task_and_split_named_task_split():
    """Each (task, split) of the datasets has its metric, named '<task>_<split>' as the per-question file reads it back
    (emml/runs/results.py, `question_rows`); a pair with none is named with the declared ones."""
    from emml.config.env import SPLITS, TASKS
    from emml.eval.evaluate import SETTINGS

    assert [(m.task, m.split) for m in metrics.EVALUATED] == [(t, s) for t in TASKS for s in SPLITS] == list(SETTINGS)
    assert all(m.name == f"{m.task}_{m.split}" for m in metrics.EVALUATED)
    with pytest.raises(ValueError, match="no metric is declared for task='sgn', split='val'; declared: sgn_test"):
        metrics.evaluated("sgn", "val")


def test_the_writers_spell_no_metric_name():
    """The evaluation and the transfer read their columns from the declaration: a writer spelling 'eqa_test' or
    'sgn_transfer' itself would write a column the declaration no longer names once it changes."""
    names = {m.name for m in DECLARED}
    found = [
        f"{path.relative_to(HOME.parent)}:{line}: {text!r}"
        for path in WRITERS
        for line, text in _literals(path)
        if text in names or text.split(":")[0] in names
    ]
    assert not found, "read these from emml/eval/metrics.py:\n" + "\n".join(found)
