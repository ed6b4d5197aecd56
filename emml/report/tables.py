"""Paper-side-by-side tables: ours (the mean over seeds, with every seed's value) beside the paper's number.

Input is the committed results/<table>/<profile>.csv (one row per finished run, written by the trainer), so a
report rebuilds without the MLflow database; the paper's numbers come from reproduce/paper/<table>.csv. The cells
and their paper-shaped layout are emml/report/cells.py's (rows are the paper's rows, columns difficulty × aux ×
metric; levels with one value move to the caption); this module writes the page around them.
Under the caption, the deviations from the paper of the runs shown, read from their saved configs
(emml/report/deviations.py); under the table, an aggregate over cells that stays honest with few seeds
(emml/report/aggregate.py).
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import pandas as pd

from emml.config.paths import project_root
from emml.config.profiles import Profile
from emml.experiments.table_data import Table
from emml.experiments.table_files import list_tables, table_ref
from emml.report.cells import (
    EXTRA_MARK,
    MISSING,
    Cell,
    build_cells,
    layout,
    level_label,
    paper_numbers,
    results_path,
    table_results,
)
from emml.report.chance import blind_prior
from emml.report.plan import ReportPlan, plan_report
from emml.runs.atomic import write_text
from emml.runs.diskspace import RERUN


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


def reports_dir(profile: Profile, out: str | Path | None = None) -> Path:
    """Where a profile's reports go: ``out``, else the committed reports/, or scratch/reports for a profile whose
    numbers are not results (smoke); a smoke report is refused under the committed reports/."""
    from emml.config.profiles import SCRATCH, is_scratch, refuse_committed

    if out is None:
        out = project_root() / (f"{SCRATCH}/reports" if is_scratch(profile) else "reports")
    refuse_committed(profile, out, "report folder")
    return Path(out)


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
    from emml.report import deviations, efficiency, questions
    from emml.report.aggregate import summary
    from emml.report.commits import commits_note
    from emml.report.field import plot_field
    from emml.report.savefig import caption_path
    from emml.report.tex import tex_table

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
    curves = [p for p in (out / f"{name}-{profile}-curves.png",) if p.exists()]
    figures = curves + [p for p in field if p.suffix == ".png"]  # every page of the field figure
    md = [f"# {name} ({profile})", "", headline(table, prof, cells), ""]
    for p in figures:  # each figure, its caption under it where one is written beside it (the curves' notes)
        note = caption_path(p)
        md += [f"![{p.stem}]({p.name})", ""] + ([note.read_text().strip(), ""] if note.exists() else [])
    md += [text, ""]
    if devs is not None:
        md += [deviations.markdown(devs), ""]
    md += [flat.to_markdown(), ""]
    names = list(dict.fromkeys(n for c in cells for n in c.runs))  # the runs behind the cells, once
    md += commits_note(results, plan.named(names))  # their commits
    if agg is not None:
        md += [pd.DataFrame(agg[0]).to_markdown(index=False), "", agg[1], ""]
    if names:
        prior = blind_prior(prof, plan.results_root)  # 'leaves chance': above what a blind model scores here
        md += [efficiency.markdown(efficiency.table_efficiency(plan, names, prior), chance=prior)]
    md += questions.section(path, cells, results)  # EQA test per question beside its blind ceiling (issue 81)
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
            label = level_label("metric", metric)
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
        parts.append(f"{level_label('difficulty', difficulty)} · {level_label('aux', aux)}: " + ", ".join(per))
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
