"""Paper-side-by-side tables: ours (mean over seeds with a 95% bootstrap CI) beside the paper's number.

Input is the committed results/<table>/<profile>.csv (one row per finished run, written by the trainer), so a
report rebuilds without the MLflow database; the paper's numbers come from reproduce/paper/<table>.csv. Cells are
joined by run name (derived from the registry), so a missing run shows as "—", never as zero. The layout follows
the paper: rows are its rows, columns difficulty × aux × metric (levels with one value move to the caption).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from emml.registry import REPRODUCE_DIR, Table, load_table
from emml.results import read_results
from emml.tracking import project_path, project_root

CONFIDENCE = 0.95
N_RESAMPLES = 9999
CI_SEED = 0
"""The bootstrap's seed: a report is reproducible to the digit."""
MISSING = "—"
EXTRA_MARK = "†"
"""Marks a row of ours that the paper's table does not have (Table 4's other test instructions)."""
DIFFICULTY_LABELS = {"easy": "Easy", "hard": "Hard", "house": "House"}
AUX_LABELS = {False: "No Aux", True: "Aux"}
METRIC_LABELS = {
    "sgn_test": "SGN test",
    "eqa_test": "EQA test",
    "sgn_train": "SGN train",
    "eqa_train": "EQA train",
    "sgn_transfer": "SGN",
}


def mean_ci(values, confidence: float = CONFIDENCE, seed: int = CI_SEED) -> tuple[float, float | None, float | None]:
    """Mean of `values` and its percentile-bootstrap CI (scipy.stats.bootstrap); (mean, None, None) for n < 2."""
    x = np.asarray(values, dtype=float)
    mean = float(np.mean(x))
    if len(x) < 2:
        return mean, None, None
    if np.all(x == x[0]):  # a degenerate bootstrap distribution: the CI is the point itself
        return mean, mean, mean
    res = stats.bootstrap(
        (x,),
        np.mean,
        confidence_level=confidence,
        method="percentile",
        n_resamples=N_RESAMPLES,
        rng=np.random.default_rng(seed),
    )
    return mean, float(res.confidence_interval.low), float(res.confidence_interval.high)


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
    mean: float | None = None
    lo: float | None = None
    hi: float | None = None

    @property
    def n(self) -> int:
        return len(self.values)

    def ours(self, all_single: bool) -> str:
        if not self.values:
            return MISSING
        text = f"{self.mean:.2f}"
        if self.lo is not None:
            text += f" [{self.lo:.2f}, {self.hi:.2f}]"
        elif not all_single:
            text += " (n=1, no CI)"
        if 1 < self.n < self.expected:
            text += f" (n={self.n}/{self.expected})"
        return text


def paper_numbers(name: str, directory: Path = REPRODUCE_DIR / "paper") -> pd.DataFrame:
    """reproduce/paper/<name>.csv as strings (values exactly as printed), aux as bool."""
    df = pd.read_csv(directory / f"{name}.csv", dtype=str, keep_default_na=False)
    df["aux"] = df["aux"].map({"true": True, "false": False})
    return df


def build_cells(table: Table, profile: str, results: pd.DataFrame, paper: pd.DataFrame) -> list[Cell]:
    """Every cell of the table (the paper's cells for a placeholder table, with no runs of ours)."""
    from emml.profiles import profile_seeds

    lookup = {(r.row, r.difficulty, r.aux, r.metric): r.value for r in paper.itertuples()}
    by_name = results.set_index("run_name") if not results.empty else pd.DataFrame()
    cells = []
    if table.placeholder:
        for r in paper.itertuples():
            cells.append(Cell(r.row, r.difficulty, r.aux, r.metric, 0, paper=r.value))
        return cells
    runs = table.runs(profile_seeds(profile))
    for row in table.rows:
        for difficulty, aux, metric in table.columns():
            specs = table.cell_runs(row.label, difficulty, aux, metric, runs)
            cell = Cell(
                row.label, difficulty, aux, metric, len(specs), paper=lookup.get((row.label, difficulty, aux, metric))
            )
            columns = table.cell_columns(row.label, metric)  # [metric], or a transfer row's instructions
            for spec in specs:
                name = spec.run_name(profile)
                if name in by_name.index and set(columns) <= set(by_name.columns):
                    found = [by_name.at[name, c] for c in columns]
                    if all(pd.notna(v) for v in found):
                        cell.values.append(float(np.mean(found)))
            if cell.values:
                cell.mean, cell.lo, cell.hi = mean_ci(cell.values)
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


def layout(table: Table, cells: list[Cell], tex: bool = False) -> tuple[pd.DataFrame, list[str]]:
    """The paper-shaped DataFrame (rows × difficulty/aux/metric columns) and the column levels held constant."""
    levels = _levels(cells)
    keep = [k for k in ("difficulty", "aux", "metric") if len(levels[k]) > 1 or k == "metric"]
    constant = [_label(k, levels[k][0]) for k in ("difficulty", "aux") if k not in keep]
    metric_labels = {v: k for k, v in table.metrics.items()}
    all_single = all(c.n <= 1 for c in cells)
    sep, missing = (r" $\mid$ ", "---") if tex else (r" \| ", MISSING)  # GFM: a bare | splits the cell
    data: dict[str, dict] = {}
    for c in cells:
        ours = c.ours(all_single).replace(MISSING, missing)
        paper = c.paper if c.paper is not None else missing
        col = tuple(
            metric_labels.get(c.metric) or _label("metric", c.metric) if k == "metric" else _label(k, getattr(c, k))
            for k in keep
        )
        data.setdefault(col, {})[c.row] = f"{ours}{sep}{paper}"
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
        return DIFFICULTY_LABELS.get(value, str(value))
    if level == "aux":
        return AUX_LABELS[bool(value)]
    return METRIC_LABELS.get(value, value)


def caption(table: Table, profile: str, cells: list[Cell], results: pd.DataFrame, constant: list[str]) -> str:
    """What the table shows, under which profile, frames and seeds, and how it was made."""
    from emml.profiles import profile_seeds

    number = table.name.removeprefix("table")
    parts = [f"Ours vs the paper's Table {number} ({table.paper_label}): {table.title}."]
    if constant:
        parts.append(f"Setting: {', '.join(constant)}.")
    if table.placeholder:
        parts.append(
            f"PLACEHOLDER: {table.path.name} declares no runs yet (status = placeholder); only the paper's "
            f"numbers are shown, ours are {MISSING}."
        )
        return " ".join(parts)
    used = results[results["run_name"].isin(_run_names(table, profile))] if not results.empty else results
    seeds = profile_seeds(profile)
    parts.append(
        f"Each cell: ours, mean over seeds [{CONFIDENCE:.0%} percentile-bootstrap CI, scipy.stats.bootstrap] | "
        f"paper; {MISSING} = run missing (not finished), never zero."
    )
    if table.transfer is not None:
        t = table.transfer
        parts.append(
            f"Each run: trained with {t.overrides}, then detectors ({t.detector}) for {', '.join(t.words)} appended, "
            "no fine-tuning (emml/transfer.py); a cell is the mean over the row's test instructions."
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
            f"{len(_run_names(table, profile))} runs finished."
        )
        if all(c.n <= 1 for c in cells):
            parts.append("n=1 seed per cell, no CI.")
    if profile != "paper":
        parts.append(
            f"The '{profile}' profile differs from the paper's protocol (frames, input size, evaluation episodes: "
            "reproduce/profiles.toml): compare orderings, not absolute numbers."
        )
    parts.append(
        f"Made by `emml run {table.name} --profile {profile}` and `emml report {table.name} --profile {profile}`."
    )
    return " ".join(parts)


def _run_names(table: Table, profile: str) -> set[str]:
    from emml.profiles import profile_seeds

    return {spec.run_name(profile) for spec in table.runs(profile_seeds(profile))}


def _tex_escape(text: str) -> str:
    for char, repl in (
        ("\\", r"\textbackslash{}"),
        ("&", r"\&"),
        ("%", r"\%"),
        ("$", r"\$"),
        ("#", r"\#"),
        ("_", r"\_"),
        ("{", r"\{"),
        ("}", r"\}"),
        ("<", r"\textless{}"),
        (">", r"\textgreater{}"),
    ):
        text = text.replace(char, repl)
    return text


def results_path(name: str, profile: str, results_root: str | Path | None = None) -> Path:
    return project_path(results_root if results_root is not None else "results") / name / f"{profile}.csv"


def report_table(
    name: str, profile: str, results_root: str | Path | None = None, out: str | Path | None = None
) -> dict:
    """Write reports/<name>-<profile>.md and .tex; returns the cells, caption and paths (the --json output)."""
    table = load_table(name)
    path = results_path(name, profile, results_root)
    results = read_results(path)
    cells = build_cells(table, profile, results, paper_numbers(name))
    md_df, constant = layout(table, cells)
    text = caption(table, profile, cells, results, constant)
    out = Path(out) if out is not None else project_root() / "reports"
    out.mkdir(parents=True, exist_ok=True)
    md_path, tex_path = out / f"{name}-{profile}.md", out / f"{name}-{profile}.tex"
    flat = md_df.copy()
    if isinstance(flat.columns, pd.MultiIndex):
        flat.columns = [" · ".join(c) for c in flat.columns]
    shown = path.relative_to(project_root()) if path.is_relative_to(project_root()) else path
    md_path.write_text(f"# {name} ({profile})\n\n{text}\n\n{flat.to_markdown()}\n\nResults: `{shown}`\n")
    tex_df, _ = layout(table, cells, tex=True)
    tex_df.index = pd.Index([_tex_escape(str(i)) for i in tex_df.index], name=table.row_header)
    tex = tex_df.reset_index().to_latex(
        index=False,
        escape=False,
        caption=_tex_escape(text).replace("—", "---").replace("–", "--").replace("|", r"$\mid$"),
        label=f"tab:ours-{name}-{profile}",
        multicolumn=True,
        multicolumn_format="c",
        column_format="l" + "c" * tex_df.shape[1],
    )
    tex_path.write_text(tex)
    return {
        "table": name,
        "profile": profile,
        "results": str(path),
        "caption": text,
        "cells": [{**asdict(c), "n": c.n} for c in cells],
        "paths": [str(md_path), str(tex_path)],
    }
