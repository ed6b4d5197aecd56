"""A table's cells: per row, difficulty, aux and metric, our runs' values (one per finished seed, from the results
CSVs) beside the paper's number as printed (reproduce/paper/<table>.csv), and the paper-shaped layout of them that
the markdown page (emml/report/tables.py) and the LaTeX table (emml/report/tex.py) both print. Cells are joined by
run name (the report's plan, emml/report/plan.py), so a missing run shows as "—", never as zero."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from emml.config.env_kinds import ENV_KINDS, env_label
from emml.config.paths import REPRODUCE_DIR, project_path
from emml.config.profiles import Profile
from emml.config.schema import TrainConfig
from emml.eval.metrics import label as metric_label
from emml.experiments.table_data import Table
from emml.report.plan import ReportPlan
from emml.runs.results import read_results

MISSING = "—"
EXTRA_MARK = "†"
"""Marks a row of ours that the paper's table does not have (Table 4's other test instructions)."""
DIFFICULTY_LABELS = {k.name: k.label for k in ENV_KINDS.values()}
"""How a difficulty column is headed (emml/config/env_kinds.py)."""
AUX_LABELS = {False: "No Aux", True: "Aux"}
PAPER_DIR = REPRODUCE_DIR / "paper"
"""The paper's numbers, a CSV per table as printed (`paper_numbers`)."""


@dataclass
class Cell:
    """One cell of the report: our runs' values and the paper's number."""

    row: str
    difficulty: str
    aux: bool
    metric: str
    expected: int
    """Runs (seeds) the registry declares for the cell under the profile."""
    values: list[float] = field(default_factory=list)
    """One value per finished run (seed) found in the results CSV."""
    paper: str | None = None
    """The paper's number exactly as printed, None if the paper has no such cell."""
    runs: list[str] = field(default_factory=list)
    """The run names behind `values`, in the same (seed) order."""

    @property
    def n(self) -> int:
        return len(self.values)

    @property
    def mean(self) -> float | None:
        return float(np.mean(self.values)) if self.values else None

    def ours(self) -> str:
        """'0.42 (0.34 · 0.34 · 0.59)': the mean and each seed's value; '(0.34 · 0.50; n=2/3)' when seeds are
        missing; one seed of one declared: the value alone."""
        if not self.values:
            return MISSING
        text = f"{self.mean:.2f}"
        seeds = " · ".join(f"{v:.2f}" for v in self.values) if self.n > 1 else ""
        partial = f"n={self.n}/{self.expected}" if self.n < self.expected else ""
        inside = "; ".join(x for x in (seeds, partial) if x)
        return f"{text} ({inside})" if inside else text


def paper_numbers(name: str, directory: Path | None = None) -> pd.DataFrame:
    """reproduce/paper/<name>.csv (``directory``: `PAPER_DIR`, read when called) as strings (values exactly as
    printed), aux as bool; no rows for a table the paper does not have (a researcher's own table: its cells show ours
    only)."""
    directory = PAPER_DIR if directory is None else Path(directory)
    path = directory / f"{name}.csv"
    if not path.exists():
        return pd.DataFrame({c: pd.Series(dtype=str) for c in ("row", "difficulty", "aux", "metric", "value")})
    df = pd.read_csv(path, dtype=str, keep_default_na=False)
    df["aux"] = df["aux"].map({"true": True, "false": False})
    return df


def build_cells(plan: ReportPlan, results: pd.DataFrame, paper: pd.DataFrame) -> list[Cell]:
    """Every cell of the table (the paper's cells for a placeholder table, with no runs of ours); each run's name
    as the plan spelled it."""
    table = plan.table

    lookup = {(r.row, r.difficulty, r.aux, r.metric): r.value for r in paper.itertuples()}
    by_name = results.set_index("run_name") if not results.empty else pd.DataFrame()
    cells = []
    if table.placeholder:
        for r in paper.itertuples():
            cells.append(Cell(r.row, r.difficulty, r.aux, r.metric, 0, paper=r.value))
        return cells
    for row in table.rows:
        for difficulty, aux, metric in table.columns():
            runs = plan.cell_runs(row.label, difficulty, aux, metric)
            cell = Cell(
                row.label, difficulty, aux, metric, len(runs), paper=lookup.get((row.label, difficulty, aux, metric))
            )
            columns = table.cell_columns(row.label, metric)  # [metric], or a transfer row's instructions
            for name in (run.name for run in runs):
                if name in by_name.index and set(columns) <= set(by_name.columns):
                    found = [by_name.at[name, c] for c in columns]
                    if all(pd.notna(v) for v in found):
                        cell.values.append(float(np.mean(found)))
                        cell.runs.append(name)
            cells.append(cell)
    return cells


def levels(cells: list[Cell]) -> dict[str, list]:
    """Distinct difficulty, aux and metric values in order of appearance."""
    out: dict[str, list] = {"difficulty": [], "aux": [], "metric": []}
    for c in cells:
        for key in out:
            if getattr(c, key) not in out[key]:
                out[key].append(getattr(c, key))
    return out


def layout(table: Table, cells: list[Cell]) -> tuple[pd.DataFrame, list[str]]:
    """The paper-shaped DataFrame (rows × difficulty/aux/metric columns) and the column levels held constant."""
    column_levels = levels(cells)
    keep = [k for k in ("difficulty", "aux", "metric") if len(column_levels[k]) > 1 or k == "metric"]
    constant = [level_label(k, column_levels[k][0]) for k in ("difficulty", "aux") if k not in keep]
    metric_labels = {v: k for k, v in table.metrics.items()}
    data: dict[str, dict] = {}
    for c in cells:
        paper = c.paper if c.paper is not None else MISSING
        metric = metric_labels.get(c.metric) or level_label("metric", c.metric)
        col = tuple(metric if k == "metric" else level_label(k, getattr(c, k)) for k in keep)
        data.setdefault(col, {})[c.row] = f"{c.ours()} \\| {paper}"  # GFM: a bare | splits the cell
    rows = list(dict.fromkeys(c.row for c in cells))
    df = pd.DataFrame(data, index=rows)
    extra = {r.label for r in table.rows if r.extra}
    df.index = [f"{r} {EXTRA_MARK}" if r in extra else r for r in rows]  # rows of ours, not in the paper
    df.index.name = table.row_header
    if len(keep) > 1:
        df.columns = pd.MultiIndex.from_tuples(df.columns)
    else:
        df.columns = [c[0] for c in df.columns]
    return df, constant


def level_label(level: str, value) -> str:
    """A column level's value as the page heads it: a difficulty's label, Aux / No Aux, a metric's label."""
    if level == "difficulty":
        return env_label(value)
    if level == "aux":
        return AUX_LABELS[bool(value)]
    return metric_label(value)


def results_path(name: str, profile: Profile, results_root: str | Path | None = None) -> Path:
    """results/<name>/<profile>.csv under ``results_root`` (default: the profile's, `results` but for smoke)."""
    if results_root is None:
        results_root = profile.values.get("results_root", TrainConfig.results_root)
    return project_path(results_root) / name / f"{profile.name}.csv"


def table_results(table: Table, profile: Profile, results_root: str | Path | None = None) -> pd.DataFrame:
    """The results rows of the table's runs under ``profile``: its own CSV, and the CSVs of the tables some of its
    rows borrow runs from (`from_table`: Table 3's "DA Multi-Task" is Table 2's Dual-Attention)."""
    owners = dict.fromkeys([table.name, *(spec.table for spec in table.runs(list(profile.seeds), profile.name))])
    frames = [read_results(results_path(owner, profile, results_root)) for owner in owners]
    frames = [f for f in frames if not f.empty]
    if not frames:
        return read_results(results_path(table.name, profile, results_root))
    return pd.concat(frames, ignore_index=True).drop_duplicates("run_name")
