"""A table's report planned once (issue 64), as its launch is: the profile resolved, the table loaded, and every
run's config built and its name spelled once by the launch's own plan (`emml.experiments.plan.plan_runs`). The
page, its caption, its LaTeX, its rliable figure, its deviations, its sample efficiency and the claims read this
value; none resolves the profile or rebuilds a run's config again (a Table 2 report built 1,448 TrainConfigs for its
84 runs before; now 2 per run, the config and the baseline its name is compared with)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from emml.config.profiles import Profile, resolve_profile
from emml.config.schema import TrainConfig
from emml.experiments.plan import PlannedRun, plan_runs
from emml.experiments.runspec import RunSpec
from emml.experiments.table_data import Table
from emml.experiments.tables import load_table


@dataclass(frozen=True)
class ReportPlan:
    """What a table's report reads: the table, the profile, every run it declares (planned) and the roots."""

    table: Table
    profile: Profile
    runs: tuple[PlannedRun, ...]
    """Every run the table declares under the profile, in the table's order (none for a placeholder)."""
    run_root: str | Path
    """Where the runs' dirs are read (their saved configs, metrics.csv, commits): the profile's unless given."""
    results_root: str | Path
    """Where the results CSVs are read: the profile's unless given."""

    @property
    def names(self) -> set[str]:
        """The run names the table declares under the profile."""
        return {r.name for r in self.runs}

    def by_name(self) -> dict[str, PlannedRun]:
        return {r.name: r for r in self.runs}

    def named(self, names) -> list[PlannedRun]:
        """The planned runs of ``names`` (run names the plan holds, e.g. a cell's), in that order: their folders,
        configs and states as planned."""
        planned = self.by_name()
        return [planned[name] for name in names]

    def no_aux_of(self, run: PlannedRun) -> PlannedRun | None:
        """The No-Aux run the table declares beside ``run``: the same row, difficulty and seed without the auxiliary
        task (its `noaux_overrides` included: a warm-up's run, not ``run`` with aux off); None when it declares
        none."""
        spec = run.spec
        beside = (spec.row, spec.difficulty, spec.seed)
        return next(
            (r for r in self.runs if not r.spec.aux and (r.spec.row, r.spec.difficulty, r.spec.seed) == beside), None
        )

    def cell_runs(self, row: str, difficulty: str, aux: bool, metric: str) -> list[PlannedRun]:
        """The planned runs (one per seed) whose `metric` fills the cell (`Table.cell_runs`)."""
        specs = self.table.cell_runs(row, difficulty, aux, metric, [r.spec for r in self.runs])
        chosen = {id(s) for s in specs}  # the plan holds the table's own RunSpecs
        return [r for r in self.runs if id(r.spec) in chosen]

    def run_of(self, spec: RunSpec) -> PlannedRun:
        """The planned run of ``spec`` (one of `Table.runs` under the profile's seeds)."""
        return next(r for r in self.runs if r.spec == spec)


def plan_report(
    table: str | Table,
    profile: Profile | str,
    results_root: str | Path | None = None,
    run_root: str | Path | None = None,
) -> ReportPlan:
    """The report of ``table`` under ``profile`` planned: the one place a report resolves its profile and names its
    runs (``results_root``/``run_root``: the profile's unless given)."""
    prof = resolve_profile(profile)
    table = table if isinstance(table, Table) else load_table(table)
    fields = {k: str(v) for k, v in (("run_root", run_root), ("results_root", results_root)) if v is not None}
    runs = () if table.placeholder else tuple(plan_runs(table.name, prof, fields, table=table))
    return ReportPlan(
        table,
        prof,
        runs,
        run_root if run_root is not None else prof.values.get("run_root", TrainConfig.run_root),
        results_root if results_root is not None else prof.values.get("results_root", TrainConfig.results_root),
    )
