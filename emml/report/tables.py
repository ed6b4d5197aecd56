"""Paper-side-by-side tables: ours (the mean over seeds, with every seed's value) beside the paper's number.

Input is the committed results/<table>/<profile>.csv (one row per finished run, written by the trainer), so a
report rebuilds without the MLflow database; the paper's numbers come from reproduce/paper/<table>.csv. Cells are
joined by run name (derived from the registry), so a missing run shows as "—", never as zero. The layout follows
the paper: rows are its rows, columns difficulty × aux × metric (levels with one value move to the caption).
Under the caption, the deviations from the paper of the runs shown, read from their saved configs
(emml/report/deviations.py); under the table, an aggregate over cells that stays honest with few seeds
(emml/report/aggregate.py).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from emml.config.env_kinds import ENV_KINDS, env_label
from emml.config.paths import REPRODUCE_DIR, project_path, project_root
from emml.config.profiles import Profile
from emml.config.schema import TrainConfig
from emml.experiments.metrics import label as metric_label
from emml.experiments.tables import Table, list_tables, table_ref
from emml.report.plan import ReportPlan, plan_report
from emml.runs.atomic import write_text
from emml.runs.diskspace import RERUN
from emml.runs.results import read_results

MISSING = "—"
EXTRA_MARK = "†"
"""Marks a row of ours that the paper's table does not have (Table 4's other test instructions)."""
DIFFICULTY_LABELS = {k.name: k.label for k in ENV_KINDS.values()}
"""How a difficulty column is headed (emml/config/env_kinds.py)."""
AUX_LABELS = {False: "No Aux", True: "Aux"}


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


def paper_numbers(name: str, directory: Path = REPRODUCE_DIR / "paper") -> pd.DataFrame:
    """reproduce/paper/<name>.csv as strings (values exactly as printed), aux as bool; no rows for a table the paper
    does not have (a researcher's own table: its cells show ours only)."""
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


def _levels(cells: list[Cell]) -> dict[str, list]:
    """Distinct difficulty, aux and metric values in order of appearance."""
    out: dict[str, list] = {"difficulty": [], "aux": [], "metric": []}
    for c in cells:
        for key in out:
            if getattr(c, key) not in out[key]:
                out[key].append(getattr(c, key))
    return out


def layout(table: Table, cells: list[Cell]) -> tuple[pd.DataFrame, list[str]]:
    """The paper-shaped DataFrame (rows × difficulty/aux/metric columns) and the column levels held constant."""
    levels = _levels(cells)
    keep = [k for k in ("difficulty", "aux", "metric") if len(levels[k]) > 1 or k == "metric"]
    constant = [_label(k, levels[k][0]) for k in ("difficulty", "aux") if k not in keep]
    metric_labels = {v: k for k, v in table.metrics.items()}
    data: dict[str, dict] = {}
    for c in cells:
        paper = c.paper if c.paper is not None else MISSING
        col = tuple(
            metric_labels.get(c.metric) or _label("metric", c.metric) if k == "metric" else _label(k, getattr(c, k))
            for k in keep
        )
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


def _label(level: str, value) -> str:
    if level == "difficulty":
        return env_label(value)
    if level == "aux":
        return AUX_LABELS[bool(value)]
    return metric_label(value)


def caption(
    plan: ReportPlan, cells: list[Cell], results: pd.DataFrame, constant: list[str], plugins: tuple[str, ...] = ()
) -> str:
    """What the table shows, under which profile, frames and seeds, and how it was made (``plugins``: the
    `--plugin`s the table's models need, which the commands that made it name)."""
    table, profile = plan.table, plan.profile.name
    paper = table.name in list_tables()  # one of reproduce/table*.toml (as emml/report/deviations.py decides)
    if paper:
        parts = [f"Ours vs the paper's Table {table.name.removeprefix('table')} ({table.paper_label}): {table.title}."]
    else:  # an experiment beyond the paper's tables, or a table of one's own: run and reported by its file
        parts = [f"{table.title} ({table.paper_label})."]
    ref = table.name if paper else table_ref(table.path)
    if constant:
        parts.append(f"Setting: {', '.join(constant)}.")
    if table.placeholder:
        parts.append(
            f"PLACEHOLDER: {table.path.name} declares no runs yet (status = placeholder); only the paper's "
            f"numbers are shown, ours are {MISSING}."
        )
        return " ".join(parts)
    used = results[results["run_name"].isin(plan.names)] if not results.empty else results
    seeds = list(plan.profile.seeds)
    parts.append(
        "Each cell: ours, the mean over seeds (each seed's value, in seed order) | paper; n=k/N: k of the N "
        f"declared seeds finished; {MISSING} = run missing (not finished), never zero."
    )
    if table.transfer is not None:
        t = table.transfer
        parts.append(
            f"Each run: trained with {t.overrides}, then detectors ({t.detector}) for {', '.join(t.words)} appended, "
            "no fine-tuning (emml/eval/transfer.py); a cell is the mean over the row's test instructions."
        )
        if any(r.extra for r in table.rows):
            parts.append(f"Rows marked {EXTRA_MARK}: the test instructions the paper's rows do not name.")
    if used.empty:
        parts.append(f"Profile '{profile}': no finished runs yet.")
    else:
        lo, hi = int(used["frames"].min()), int(used["frames"].max())
        frames = f"{lo:,}" if lo == hi else f"{lo:,}–{hi:,}"
        found = sorted(int(s) for s in used["seed"].unique())
        parts.append(
            f"Profile '{profile}': {frames} frames trained per run; seeds {', '.join(map(str, found))} "
            f"of {len(seeds)} declared ({', '.join(map(str, seeds))}); {len(used)} of "
            f"{len(plan.names)} runs finished."
        )
    if profile != "paper":
        parts.append(
            f"The '{profile}' profile is not the paper's protocol (its deviations from the paper, read from the runs' "
            "configs, are listed here): compare orderings, not absolute numbers."
        )
    emml = " ".join(["emml", *(f"--plugin {_shown_path(p)}" for p in plugins)])  # a model of one's own needs its plugin
    parts.append(f"Made by `{emml} run {ref} --profile {profile}` and `{emml} report {ref} --profile {profile}`.")
    return " ".join(parts)


def _shown_path(plugin: str) -> str:
    """A plugin as a reader types it: a path under the checkout relative to it (`EMML_PLUGINS` holds it absolute)."""
    path = Path(plugin)
    inside = path.is_absolute() and path.is_relative_to(project_root())
    return str(path.relative_to(project_root())) if inside else plugin


def shown_runs(plan: ReportPlan, cells: list[Cell], results: pd.DataFrame) -> list:
    """The runs behind the table's cells with their configs (emml/report/deviations.py); every declared run when none
    has finished (its deviations as declared); [] for a placeholder."""
    from emml.report.deviations import shown_run

    if plan.table.placeholder:
        return []
    planned = plan.by_name()
    names = list(dict.fromkeys(name for c in cells for name in c.runs))
    if not names:
        return [shown_run(run, plan.run_root, declared=True) for run in planned.values()]
    rows = {r["run_name"]: r for r in results.to_dict("records")} if not results.empty else {}
    return [shown_run(planned[name], plan.run_root, rows.get(name)) for name in names]


def results_path(name: str, profile: Profile, results_root: str | Path | None = None) -> Path:
    """results/<name>/<profile>.csv under ``results_root`` (default: the profile's, `results` but for smoke)."""
    if results_root is None:
        results_root = profile.values.get("results_root", TrainConfig.results_root)
    return project_path(results_root) / name / f"{profile.name}.csv"


def reports_dir(profile: Profile, out: str | Path | None = None) -> Path:
    """Where a profile's reports go: ``out``, else the committed reports/, or scratch/reports for a profile whose
    numbers are not results (smoke); a smoke report is refused under the committed reports/."""
    from emml.config.profiles import SCRATCH, is_scratch, refuse_committed

    if out is None:
        out = project_root() / (f"{SCRATCH}/reports" if is_scratch(profile) else "reports")
    refuse_committed(profile, out, "report folder")
    return Path(out)


def table_results(table: Table, profile: Profile, results_root: str | Path | None = None) -> pd.DataFrame:
    """The results rows of the table's runs under ``profile``: its own CSV, and the CSVs of the tables some of its
    rows borrow runs from (`from_table`: Table 3's "DA Multi-Task" is Table 2's Dual-Attention)."""
    owners = dict.fromkeys([table.name, *(spec.table for spec in table.runs(list(profile.seeds)))])
    frames = [read_results(results_path(owner, profile, results_root)) for owner in owners]
    frames = [f for f in frames if not f.empty]
    if not frames:
        return read_results(results_path(table.name, profile, results_root))
    return pd.concat(frames, ignore_index=True).drop_duplicates("run_name")


def report_table(
    name: str,
    profile: Profile | str,
    results_root: str | Path | None = None,
    out: str | Path | None = None,
    run_root: str | Path | None = None,
    plugins: list[str] | tuple[str, ...] = (),
) -> dict:
    """Write reports/<name>-<profile>.md and .tex; returns the cells, caption, deviations, aggregate and paths (the
    --json output). Runs' configs are read from their run dirs under ``run_root`` (default: the profile's).
    ``plugins``: the `--plugin`s the report was made with (a table of one's own), named in its "Made by" line.

    Planned once (issue 64): the profile resolved and every run's config and name made once (`plan_report`, the
    launch's own `plan_runs`); every part of the page reads that plan."""
    from emml.report import deviations, efficiency
    from emml.report.aggregate import summary
    from emml.report.field import plot_field
    from emml.report.tex import tex_table
    from emml.runs.segments import commits_note

    plan = plan_report(name, profile, results_root, run_root)
    table, prof = plan.table, plan.profile
    name, profile = table.name, prof.name  # a table file's path (one's own, an experiment) reports under its stem
    out = reports_dir(prof, out)
    path = results_path(name, prof, plan.results_root)
    results = table_results(table, prof, plan.results_root)
    cells = build_cells(plan, results, paper_numbers(name))
    md_df, constant = layout(table, cells)
    text = caption(plan, cells, results, constant, tuple(plugins))
    runs = shown_runs(plan, cells, results)
    devs = deviations.summarise(runs, deviations.noaux_schedule(plan)) if runs else None
    agg = summary(table, cells)
    out.mkdir(parents=True, exist_ok=True)
    md_path, tex_path = out / f"{name}-{profile}.md", out / f"{name}-{profile}.tex"
    flat = md_df.copy()
    if isinstance(flat.columns, pd.MultiIndex):
        flat.columns = [" · ".join(c) for c in flat.columns]
    shown = path.relative_to(project_root()) if path.is_relative_to(project_root()) else path
    field = plot_field(table, prof, cells, out)
    figures = [p for p in (out / f"{name}-{profile}-curves.png",) if p.exists()] + field[:1]
    md = [f"# {name} ({profile})", "", headline(table, prof, cells), ""]
    md += [f"![{p.stem}]({p.name})" for p in figures] + ([""] if figures else [])
    md += [text, ""]
    if devs is not None:
        md += [deviations.markdown(devs), ""]
    md += [flat.to_markdown(), ""]
    md += commits_note(results, list(dict.fromkeys(n for c in cells for n in c.runs)), plan.run_root)  # their commits
    if agg is not None:
        md += [pd.DataFrame(agg[0]).to_markdown(index=False), "", agg[1], ""]
    names = list(dict.fromkeys(n for c in cells for n in c.runs))
    if names:
        from emml.report.chance import blind_prior

        prior = blind_prior(prof, plan.results_root)  # 'leaves chance': above what a blind model scores here
        md += [efficiency.markdown(efficiency.table_efficiency(plan, names, prior), chance=prior)]
    md += [f"Results: `{shown}`", ""]
    write_text(md_path, "\n".join(md), then=RERUN)  # whole or not at all (emml/runs/atomic.py)
    write_text(tex_path, tex_table(plan, cells, results, devs), then=RERUN)
    return {
        "table": name,
        "profile": profile,
        "results": str(path),
        "caption": text,
        "deviations": asdict(devs) if devs is not None else None,
        "aggregate": {"rows": agg[0], "footer": agg[1]} if agg is not None else None,
        "cells": [{**asdict(c), "n": c.n, "mean": c.mean} for c in cells],
        "paths": [str(md_path), str(tex_path), *map(str, field)],
    }


def headline(table: Table, profile: Profile, cells: list[Cell]) -> str:
    """The page's first line: per setting and metric with runs, where the reference row (Dual-Attention) stands and
    the row that leads; the seeds it rests on; where the claims are decided."""
    from emml.report.aggregate import reference_row

    ref = reference_row(table)
    parts = []
    groups: dict[tuple, list[Cell]] = {}
    for c in cells:
        if c.values:
            groups.setdefault((c.difficulty, c.aux), []).append(c)
    for (difficulty, aux), group in groups.items():
        per = []
        for metric in dict.fromkeys(c.metric for c in group):
            ranked = sorted((c for c in group if c.metric == metric), key=lambda c: -c.mean)
            label = _label("metric", metric)
            top = ranked[0]
            mine = next((c for c in ranked if c.row == ref), None)
            if len(ranked) == 1:
                per.append(f"{label} {top.row} {top.mean:.2f} (the only row run)")
            elif mine is None:
                per.append(f"{label} best {top.row} {top.mean:.2f} of {len(ranked)} rows")
            elif mine is top:
                per.append(
                    f"{label} {ref} first of {len(ranked)} ({mine.mean:.2f}; next {ranked[1].row} {ranked[1].mean:.2f})"
                )
            else:
                rank = ranked.index(mine) + 1
                per.append(f"{label} {ref} {rank} of {len(ranked)} ({mine.mean:.2f}; {top.row} {top.mean:.2f})")
        parts.append(f"{_label('difficulty', difficulty)} · {_label('aux', aux)}: " + ", ".join(per))
    seeds = sorted({c.n for c in cells if c.values})
    if not parts:
        return f"**In one line**: no run of {table.name} has finished under '{profile.name}' yet."
    rest = (
        f"; {seeds[0]}–{seeds[-1]} seeds per cell"
        if len(seeds) > 1
        else f"; {seeds[0]} seed{'s' if seeds[0] != 1 else ''} per cell"
    )
    page = f"claims-{profile.name}.md"
    claims = f" Claims decided on [{page}]({page})." if table.name in list_tables() else ""
    return f"**In one line** ({profile.name}{rest}): " + "; ".join(parts) + "." + claims
