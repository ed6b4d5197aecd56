"""The metrics, each declared once: its results column, the label the paper's tables head it with, its task and
split, whether it is an accuracy, which chance it is held against, its curve's colour, the metrics-mirror (MLflow)
key its curve is read from, and whether it is a training-split column.

It lives in the evaluation's wing because the evaluation writes the values: the greedy evaluation scores each
(task, split) into its metric's column (`evaluated`, emml/eval/evaluate.py), Table 4's transfer into its metric's
`<name>:<instruction>` columns (`TRANSFER_METRIC`, emml/eval/transfer.py). The layers (pyproject.toml) let every wing
above read it, and no wing below it needs it; declared in emml/experiments/ it was out of the writers' reach.

Every reader reads this: the trainer's log keys (emml/rl/), the table files' allowed columns
(emml/experiments/tables.py), the claims (emml/experiments/claims/), the chance (emml/report/chance.py,
emml/experiments/claims/evidence.py), the pages' labels (emml/report/tables.py, field.py, efficiency.py), the curves
and their colours (emml/report/curves.py), the train columns (emml/report/index.py, claims.py) and the results
payload (emml/report/saved_config.py).
"""

from __future__ import annotations

from dataclasses import dataclass

from emml.config.env import SPLITS, TASKS

TRANSFER = "transfer"
"""The split of a metric scored on instructions with words the run never trained on (Table 4)."""
METRIC_SPLITS = (*SPLITS, TRANSFER)
"""A metric's split: a dataset split (emml/config/env.py, `SPLITS`) or the transfer's new instructions."""


@dataclass(frozen=True)
class Metric:
    """One results column and how every page shows it."""

    name: str
    """The results column (results/<table>/<profile>.csv, results.json "metrics"): sgn_test, eqa_train, ..."""
    label: str
    """How the reports head its column (the paper's Tables 2-5: 'SGN', 'EQA'; train and test apart)."""
    task: str
    """'sgn' or 'eqa'."""
    split: str
    """One of `METRIC_SPLITS`: 'train', 'test', or 'transfer' (Table 4: one column `<name>:<instruction>` per new
    instruction)."""
    key: str
    """The metrics-mirror (MLflow) key its curve is read from: `eval/<name>`, logged every `eval_every` frames; a
    transfer metric, scored once after training, draws its runs' training split."""
    colour: str
    """The matplotlib colour of its greedy-evaluation curve (emml/report/curves.py)."""
    uniform: float
    """The floor of its chance: SGN walks to one of the 5 objects; EQA gives one of the answers a question allows, as
    the paper's Text only row scores (0.33 in every column of its Table 2)."""
    chance: str
    """The column whose measured blind prior (the Text only row, emml/report/chance.py) it is held against, never
    below `uniform`: itself, or for a transfer instruction (unseen) the task's test column."""
    accuracy: bool = True
    """A success rate in [0, 1] (an accuracy axis, a chance line)."""
    curve_label: str = ""
    """The label of its curve's panels, when it is not `label`."""

    @property
    def train_column(self) -> bool:
        """A training-split column: whether a run has learned its task is read on it."""
        return self.split == "train"

    @property
    def periodic(self) -> bool:
        """Whether its greedy evaluation is logged periodically as `eval/<name>` (a sample-efficiency curve)."""
        return self.key == f"eval/{self.name}"

    def column(self, instruction: str) -> str:
        """A transfer metric's results column for one instruction: `<name>:<instruction>`."""
        return f"{self.name}:{instruction}"

    @property
    def curve(self) -> str:
        return self.curve_label or self.label


DECLARED = (
    Metric("sgn_test", "SGN test", "sgn", "test", "eval/sgn_test", "C2", 0.2, "sgn_test"),
    Metric("eqa_test", "EQA test", "eqa", "test", "eval/eqa_test", "C3", 1 / 3, "eqa_test"),
    Metric("sgn_train", "SGN train", "sgn", "train", "eval/sgn_train", "C0", 0.2, "sgn_train"),
    Metric("eqa_train", "EQA train", "eqa", "train", "eval/eqa_train", "C1", 1 / 3, "eqa_train"),
    Metric(
        "sgn_transfer",
        "SGN",
        "sgn",
        TRANSFER,
        "eval/sgn_train",
        "C0",
        0.2,
        "sgn_test",
        curve_label="SGN train (before the transfer)",
    ),
)
"""Every metric, in the order the pages list them."""
BY_NAME = {m.name: m for m in DECLARED}


def metric(name: str) -> Metric:
    """The declaration of a results column; a transfer table's `sgn_transfer:<instruction>` is its metric's."""
    return BY_NAME[name.split(":")[0]]


def is_metric(column: str) -> bool:
    """Whether a results column holds a metric (a transfer instruction's column included)."""
    return column.split(":")[0] in BY_NAME


def label(name: str) -> str:
    """The column head of a metric; anything else as it is."""
    return BY_NAME[name].label if name in BY_NAME else name


def train_of(task: str) -> Metric:
    """The training-split column of a task (whether a run has learned it)."""
    return next(m for m in DECLARED if m.train_column and m.task == task)


METRICS = tuple(m.name for m in DECLARED if m.split != TRANSFER)
"""Results columns a cell of a table may read (written by the trainer's greedy evaluation)."""
TRANSFER_METRICS = tuple(m.name for m in DECLARED if m.split == TRANSFER)
"""What a transfer table's cells read: the mean of their instructions' `<name>:<instruction>` columns."""
CURVE_METRICS = tuple(m.name for m in DECLARED if m.periodic)
"""The results columns whose greedy evaluation is logged periodically as `eval/<metric>`."""
TRAIN_COLUMNS = tuple(m.name for m in DECLARED if m.train_column)
"""The training-split columns, one per task."""
CHANCE_COLUMNS = tuple(dict.fromkeys(m.chance for m in DECLARED))
"""The columns a blind prior is measured on (emml/report/chance.py)."""
UNIFORM = {m.task: m.uniform for m in DECLARED}
"""The floor of chance per task."""


def evaluated(task: str, split: str) -> Metric:
    """The metric the greedy evaluation writes for one (task, split) of a dataset (its results column, `eval/<name>`
    curve and `final/<name>` score); a pair with no declared metric is a ValueError naming the declared ones."""
    for m in DECLARED:
        if (m.task, m.split) == (task, split):
            return m
    raise ValueError(f"no metric is declared for task={task!r}, split={split!r}; declared: {', '.join(METRICS)}")


EVALUATED = tuple(evaluated(task, split) for task in TASKS for split in SPLITS)
"""The metrics the greedy evaluation writes, one per (task, split), in the order it plays them: task by task, each
split in `SPLITS` order."""
TRANSFER_METRIC = next(m for m in DECLARED if m.split == TRANSFER)
"""The metric Table 4's transfer writes, one column per instruction (`Metric.column`)."""
