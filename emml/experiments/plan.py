"""A table's runs planned: each run's config built and its name spelled once (`plan_runs`), with its state here
(`STATES`: its results CSV and run dir read once), the runs chosen by their RunSpec fields (`select_runs`) and given a
launch's overrides of how they run (`with_overrides`). The launcher, the process pool, Slurm, the campaigns and the
report all read these `PlannedRun`s: a run's folder, config, name and state come from here and are not rebuilt."""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from pathlib import Path

from emml.config.profiles import Profile, resolve_profile
from emml.config.schema import TrainConfig, apply_overrides
from emml.experiments.runspec import RunSpec
from emml.experiments.table_data import Table
from emml.experiments.tables import load_table
from emml.runs.naming import run_name

STATES = ("finished", "unrecorded", "reference", "partial", "missing")
"""finished: a finished run dir here and its row in the results CSV; unrecorded: run dir finished but no CSV row;
reference: a CSV row with no run dir here (results committed to the repository, or made on another machine):
trained here, its row then replaced; partial: interrupted (a checkpoint, not finished); missing: nothing yet."""
ONLY_FIELDS = ("row", "model", "difficulty", "aux", "seed")
"""RunSpec fields `emml run --only FIELD=VALUE` (and a campaign step's `only`) can select on."""


@dataclass(frozen=True)
class PlannedRun:
    """One run of a table under a profile: its config built and its name spelled once (`plan_runs`), then handed to
    whoever trains it (this process, a pool worker, a Slurm job) or reads it (a campaign's status, a report) as it
    is."""

    spec: RunSpec
    """What the table (and a campaign step's overrides) declares."""
    cfg: TrainConfig
    """Its TrainConfig under the plan's profile, with the plan's run_root, results_root, device, threads."""
    name: str
    """Its run name (`emml.runs.naming.run_name`)."""
    state: str
    """Its state here when planned (STATES)."""

    @property
    def directory(self) -> Path:
        """Its run dir (`emml.runs.rundir.path_of`: from the name already spelled, not spelled again)."""
        from emml.runs.rundir import path_of

        return path_of(self.cfg.run_root, self.cfg.table, self.name)


def plan_runs(
    name: str,
    profile: Profile,
    fields: dict | None = None,
    only: dict | None = None,
    overrides: dict | None = None,
    table: Table | None = None,
) -> list[PlannedRun]:
    """Every run of table `name` under `profile`, in training order: `only` selects and `overrides` apply on top of
    each run's own (`chosen`); `fields` (run_root, results_root, device, threads) go to every run's TrainConfig.
    `table`: `name` already loaded (a report's plan, emml/report/plan.py), not loaded again. Two rows declaring one
    run (one name) plan it once, where it first appears."""
    fields = fields or {}
    table = table if table is not None else load_table(name)
    planned: dict[str, PlannedRun] = {}
    recorded: dict[Path, set[str]] = {}  # per results CSV: a row may borrow another table's runs (from_table)
    for spec in table.runs(list(profile.seeds), profile.name):
        cfg = spec.to_config(profile, **fields)
        rname = run_name(cfg, profile)
        planned[rname] = PlannedRun(spec, cfg, rname, run_state(cfg, rname, table, spec, recorded))
    return chosen(list(planned.values()), only, overrides)


def chosen(runs: list[PlannedRun], only: dict | None = None, overrides: dict | None = None) -> list[PlannedRun]:
    """The runs of ``runs`` that ``only`` selects, in its order (`select_runs`), each with ``overrides`` of how it
    runs on top of its own (`with_overrides`): a launch's, or a campaign step's, from a table planned once."""
    by_name = {r.name: r for r in runs}
    picked = [by_name[n] for n in select_runs({r.name: (r.spec, r.state) for r in runs}, only or {})]
    return [_overridden(r, overrides) for r in picked] if overrides else picked


def run_state(cfg: TrainConfig, rname: str, table: Table, spec: RunSpec, recorded: dict[Path, set[str]]) -> str:
    """The run's state here (STATES), from its results CSV (read once per CSV into ``recorded``) and run dir."""
    from emml.runs.results import read_results
    from emml.runs.rundir import CHECKPOINT, finished_run, path_of, results_csv

    csv = results_csv(cfg)
    if csv not in recorded:
        results = read_results(csv)
        if table.transfer is not None:  # a transfer run is recorded once its scores are in the row
            from emml.eval.transfer import metric_column

            columns = [metric_column(x) for x in spec.instructions]
            complete = set(columns) <= set(results.columns)
            results = results[results[columns].notna().all(axis=1)] if complete else results.iloc[:0]
        recorded[csv] = set(results["run_name"])
    rdir = path_of(cfg.run_root, cfg.table, rname)
    if rname in recorded[csv]:
        return "finished" if finished_run(rdir) else "partial" if (rdir / CHECKPOINT).exists() else "reference"
    if (rdir / CHECKPOINT).exists():
        return "unrecorded" if finished_run(rdir) else "partial"
    return "missing"


def _overridden(run: PlannedRun, overrides: dict) -> PlannedRun:
    spec = with_overrides(run.spec, overrides)
    return replace(run, spec=spec, cfg=apply_overrides(copy.deepcopy(run.cfg), overrides))


def run_states(name: str, profile: Profile | str, run_root: str | None = None, results_root: str | None = None) -> dict:
    """Run name → (RunSpec, state) for every run of table `name` under `profile` (see STATES)."""
    runs = plan_runs(name, resolve_profile(profile), root_fields(run_root, results_root))
    return {r.name: (r.spec, r.state) for r in runs}


def select_runs(states: dict, only: dict) -> dict:
    """The runs of `states` whose fields equal every `only` value (compared as lower-case text); a value may be a
    list of allowed values, whose order then orders the runs (a campaign's step lists them in the order it wants
    them trained; otherwise the table's order). An unknown field, or a value no run has, fails by name with the
    allowed fields or the values present."""
    wanted = {
        key: [str(v).lower() for v in (value if isinstance(value, list | tuple) else [value])]
        for key, value in only.items()
    }
    for key, values in wanted.items():
        if key not in ONLY_FIELDS:
            allowed = ", ".join(ONLY_FIELDS)
            raise ValueError(f"--only {key}={only[key]}: unknown field {key!r}; allowed fields are {allowed}")
        present = sorted({str(getattr(spec, key)).lower() for spec, _ in states.values()})
        for value in values:
            if value not in present:
                raise ValueError(f"--only {key}={value}: no run has it; the values present are {', '.join(present)}")
    selected = [
        (rname, (spec, state))
        for rname, (spec, state) in states.items()
        if all(str(getattr(spec, k)).lower() in values for k, values in wanted.items())
    ]

    def rank(item) -> tuple[int, ...]:
        return tuple(values.index(str(getattr(item[1][0], k)).lower()) for k, values in wanted.items())

    return dict(sorted(selected, key=rank))


def with_overrides(spec: RunSpec, overrides: dict) -> RunSpec:
    """`spec` with extra dotted TrainConfig overrides after its own: only fields of how a run runs
    (`TrainConfig.RUNTIME`, e.g. a campaign step's frames), so that the run stays the one its table names."""
    other = sorted(k for k in overrides if k.split(".")[0] not in TrainConfig.RUNTIME)
    if other:
        allowed = ", ".join(TrainConfig.RUNTIME)
        raise ValueError(
            f"overrides {', '.join(other)}: a launch may set only how a table's runs run ({allowed}); "
            "declare another experiment as a row of the table"
        )
    return replace(spec, overrides={**spec.overrides, **overrides})


def root_fields(run_root: str | None, results_root: str | None) -> dict:
    """The TrainConfig fields of the roots given (none for a root left to the profile)."""
    return {k: v for k, v in (("run_root", run_root), ("results_root", results_root)) if v is not None}
