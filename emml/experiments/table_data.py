"""A paper table as data: its rows (`Row`, with the seeds a setting adds, `MoreSeeds`), its columns (difficulties ×
aux × metrics) and the runs they expand to (`Table.runs`: one `RunSpec` per setting and seed), with the cells each
run fills. emml/experiments/tables.py reads and checks a table file into a `Table`."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from emml.eval.metrics import BY_NAME
from emml.experiments.runspec import RunSpec, Transfer

TRANSFER_RUN_ROW = "Training run (before transfer)"
"""The `RunSpec.row` of a transfer table's runs: one training setting serves every row (its curve's label)."""


@dataclass(frozen=True)
class MoreSeeds:
    """Seeds one setting of a row trains beyond its profile's (`more_seeds` in a table file): the stated model's
    spread (e.g. Table 2's Dual-Attention, Easy · Aux, on five seeds at the quick profile)."""

    profile: str
    """The profile they apply under (reproduce/profiles.toml); no other profile plans them."""
    difficulty: str
    """The setting's difficulty column."""
    aux: bool
    """The setting's aux column."""
    seeds: tuple[int, ...]
    """The seeds added after the profile's own."""


@dataclass(frozen=True)
class Row:
    """A row of the paper's table."""

    label: str
    """The paper's label, used to join with reproduce/paper/<table>.csv."""
    model: str
    """Model registry name."""
    overrides: dict = field(default_factory=dict)
    """Config overrides for every run of the row."""
    metric_overrides: dict = field(default_factory=dict)
    """metric → extra overrides: the row's cells of that metric come from runs with them."""
    instructions: tuple[str, ...] = ()
    """Transfer tables: the test instructions the row's cells average over."""
    extra: bool = False
    """Transfer tables: a row of ours below the paper's (test instructions its table does not list)."""
    from_table: str | None = None
    """The row's runs are that table's (same run names, run dirs and results rows), not trained again: Table 3's
    "DA Multi-Task" is Table 2's Dual-Attention."""
    noaux_overrides: dict = field(default_factory=dict)
    """Extra overrides for the row's runs without the auxiliary task only (over `overrides` and `metric_overrides`):
    Dual-Attention's No Aux runs keep the answer loss to the GA2 gate (docs/fidelity.md 'No Aux')."""
    more_seeds: tuple[MoreSeeds, ...] = ()
    """Settings of the row that train more seeds than the profile's, under one named profile (`MoreSeeds`)."""

    def seeds(self, seeds: list[int], profile: str | None, difficulty: str, aux: bool) -> list[int]:
        """The seeds of one setting: the profile's, then its `more_seeds` under that profile."""
        more = [
            s
            for m in self.more_seeds
            if (m.profile, m.difficulty, m.aux) == (profile, difficulty, aux)
            for s in m.seeds
        ]
        return list(seeds) + [s for s in more if s not in seeds]

    def settings(self, metrics: tuple[str, ...]) -> list[tuple[dict, tuple[str, ...]]]:
        """(overrides, metrics filled) for each distinct setting of the row."""
        if not self.metric_overrides:
            return [(dict(self.overrides), metrics)]
        return [({**self.overrides, **self.metric_overrides[m]}, (m,)) for m in metrics]

    def for_aux(self, overrides: dict, aux: bool) -> tuple[dict, tuple[str, ...]]:
        """A setting's overrides for its runs with (``aux``) or without the auxiliary task, and which of them depart
        from the paper (`RunSpec.departures`: the No Aux overrides)."""
        extra = {} if aux else self.noaux_overrides
        return {**overrides, **extra}, tuple(extra)


@dataclass(frozen=True)
class Table:
    """A paper table as data: rows, columns and where its numbers come from."""

    name: str
    """File stem: table2, table3, …"""
    path: Path
    """The TOML file."""
    title: str
    """The paper's caption (shortened where long)."""
    paper_label: str
    """The LaTeX label of the paper's table."""
    status: str
    """'active' (declares runs) or 'placeholder' (completed by its own issue; no runs)."""
    row_header: str = "Model"
    """Header of the row-label column."""
    rows: tuple[Row, ...] = ()
    difficulties: tuple[str, ...] = ()
    aux: tuple[bool, ...] = ()
    metrics: dict = field(default_factory=dict)
    """Column label (SGN) → results column (sgn_test), in the paper's order."""
    transfer: Transfer | None = None
    """A transfer table (Table 4): rows are instruction types read from one training setting."""

    @property
    def placeholder(self) -> bool:
        return self.status == "placeholder"

    def columns(self) -> list[tuple[str, bool, str]]:
        """(difficulty, aux, metric) for every cell column, in the paper's order."""
        return [(d, a, m) for d in self.difficulties for a in self.aux for m in self.metrics.values()]

    def runs(self, seeds: list[int], profile: str | None = None) -> list[RunSpec]:
        """Every run: rows × difficulties × aux × row settings × seeds (a transfer table: difficulties × aux ×
        seeds, every row read from them); ``profile``: the profile's name, whose rows' `more_seeds` are added (None:
        the seeds given only)."""
        out = []
        if self.transfer is not None:
            t = self.transfer
            texts = tuple(x for row in self.rows for x in row.instructions)
            metrics = tuple(self.metrics.values())
            for difficulty in self.difficulties:
                for aux in self.aux:
                    for seed in seeds:
                        out.append(
                            RunSpec(
                                self.name,
                                TRANSFER_RUN_ROW,
                                t.model,
                                difficulty,
                                aux,
                                seed,
                                t.overrides,
                                metrics,
                                t,
                                texts,
                            )
                        )
            return out
        for row in self.rows:
            for difficulty in self.difficulties:
                for aux in self.aux:
                    for overrides, metrics in row.settings(tuple(self.metrics.values())):
                        settings, departures = row.for_aux(overrides, aux)
                        owner = row.from_table or self.name
                        for seed in row.seeds(seeds, profile, difficulty, aux):
                            out.append(
                                RunSpec(
                                    owner,
                                    row.label,
                                    row.model,
                                    difficulty,
                                    aux,
                                    seed,
                                    dict(settings),
                                    metrics,
                                    departures=departures,
                                )
                            )
        return out

    def cell_runs(self, row: str, difficulty: str, aux: bool, metric: str, runs: list[RunSpec]) -> list[RunSpec]:
        """The runs (one per seed) whose `metric` fills the cell."""
        return [
            r
            for r in runs
            if (r.row == row or self.transfer is not None)
            and r.difficulty == difficulty
            and r.aux == aux
            and metric in r.metrics
        ]

    def curve_rows(self) -> list[str]:
        """The `RunSpec.row` values to draw one training curve each for: the rows, or a transfer table's one
        training setting."""
        return [TRANSFER_RUN_ROW] if self.transfer is not None else [r.label for r in self.rows]

    def cell_columns(self, row: str, metric: str) -> list[str]:
        """The results columns whose mean is a run's value for the cell: [metric], or for a transfer table one
        `<metric>:<instruction>` column per instruction of the row (`Metric.column`: Table 4's sgn_transfer, as
        emml/eval/transfer.py writes it)."""
        if self.transfer is None:
            return [metric]
        declared = BY_NAME[metric]
        return [declared.column(x) for r in self.rows if r.label == row for x in r.instructions]
