"""A metric is a declaration (issue 64 item 1): emml/experiments/metrics.py names each metric once, and no reader
spells a metric's curve key or label itself."""

import ast
from pathlib import Path

import emml
from emml.experiments import metrics
from emml.experiments.metrics import BY_NAME, DECLARED, metric

HOME = Path(emml.__file__).parent
PRODUCERS = {"eval"}
"""The wings below the declaration that write the values (the trainer's greedy evaluation, Table 4's transfer)."""


def test_each_metric_is_declared_once_with_a_known_task_split_and_chance():
    assert len(BY_NAME) == len(DECLARED)
    for m in DECLARED:
        assert m.task in metrics.TASKS and m.split in metrics.SPLITS, m
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
    spelled = {m.key for m in DECLARED} | {m.label for m in DECLARED if m.split != "transfer"}
    spelled |= {m.curve for m in DECLARED}
    found = [
        f"{path.relative_to(HOME.parent)}:{line}: {text!r}"
        for path in sorted(HOME.rglob("*.py"))
        if path != HOME / "experiments" / "metrics.py" and path.relative_to(HOME).parts[0] not in PRODUCERS
        for line, text in _literals(path)
        if text in spelled
    ]
    assert not found, "read these from emml/experiments/metrics.py:\n" + "\n".join(found)


def test_a_transfer_metrics_column_is_the_one_the_transfer_writes():
    from emml.eval.transfer import METRIC, metric_column

    assert METRIC in metrics.TRANSFER_METRICS
    assert BY_NAME[METRIC].column("go to the torch") == metric_column("go to the torch")
