"""reports/<table>-<profile>.tex: a table's report as floats a two-column paper prints as they are (issue 63).

Laid out as the paper lays its tables out: its rows are rows; a table whose difficulties each hold several columns
(Table 2: Easy and Hard × No Aux and Aux × SGN and EQA) is set as one panel per difficulty, stacked, so that no row
needs the width of both; each metric's column holds ours (the mean over the finished seeds; the seeds themselves are
on the Markdown page) beside the paper's number. Each table is a `table*` set in \\footnotesize (8 pt under a 10 pt
class) that fits a two-column page's text width unscaled: no \\resizebox. The aggregate is its own `table*` per
metric, a panel per setting. \\cmidrule under every group header; ASCII only, and only glyphs of the fonts a bare
pdflatex embeds as Type 1 (no \\S: 'Sec.'). The tabulars are pandas' Styler's; this module adds the panels and rules.
"""

from __future__ import annotations

import pandas as pd

from emml.report.cells import EXTRA_MARK, level_label, levels

TEX_PACKAGES = ("booktabs",)
"""What the .tex tables need in the preamble (stated in each file's first line)."""
TEX_CHARS = {
    "·": r"$\cdot$",
    "−": "-",
    "≥": r"$\geq$",
    "≤": r"$\leq$",
    "†": r"$\dagger$",
    "×": r"$\times$",
    "—": "---",
    "–": "--",
    "→": r"$\rightarrow$",
    "…": r"\dots{}",
    "§": "Sec.~",
}
"""Characters a bare pdflatex (no unicode packages) cannot set, as LaTeX it sets in Type 1 fonts (\\S would take its
glyph from a font that needs cm-super, else a Type 3 bitmap)."""
MISSING = "---"
"""A cell with no number (a run not finished, a number the paper does not have)."""
TABCOLSEP = "4pt"
"""Space either side of a column (LaTeX's default 6pt): Table 2's panel fits a two-column page with room to spare."""


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
        ("<", r"$<$"),
        (">", r"$>$"),
    ):
        text = text.replace(char, repl)
    return text


def tex_text(text: str) -> str:
    """Plain text as LaTeX that a minimal pdflatex document sets: specials escaped, the Unicode above replaced, any
    other non-ASCII character dropped."""
    out = _tex_escape(text).replace("|", r"$\mid$")
    for char, repl in TEX_CHARS.items():
        out = out.replace(char, repl)
    return "".join(ch for ch in out if ord(ch) < 128)


def tabular(panels: list[tuple[str | None, pd.DataFrame]], stub: str) -> str:
    """One booktabs tabular of ``panels`` (frames of LaTeX strings with the same columns, their index the row
    labels): the header from the columns' levels, a \\cmidrule under each group of a level above the last, then each
    panel's rows under its title (a row of its own, in italics; none for a title None), a \\midrule between panels.
    ``stub`` heads the row labels' column."""
    frames = [df for _, df in panels]
    whole = pd.concat(frames)
    columns = whole.columns
    if isinstance(columns, pd.MultiIndex):
        columns = columns.set_names([None] * (columns.nlevels - 1) + [stub])
    else:
        columns = columns.set_names(stub)
    whole.columns = columns
    width = whole.shape[1] + 1
    text = whole.style.to_latex(hrules=True, multicol_align="c", column_format="l" + "c" * whole.shape[1])
    lines = text.rstrip("\n").split("\n")
    top, mid = lines.index(r"\toprule"), lines.index(r"\midrule")
    header, body = lines[top + 1 : mid], lines[mid + 1 : -2]
    ruled = []
    for level, line in enumerate(header):
        ruled.append(line)
        if level < columns.nlevels - 1:
            rules = [f"\\cmidrule(lr){{{a + 2}-{b + 2}}}" for a, b in _groups(columns, level) if b > a]
            if rules:
                ruled.append(" ".join(rules))
    out, at = [], 0
    for k, (title, df) in enumerate(panels):
        if k:
            out.append(r"\midrule")
        if title is not None:
            out.append(f"\\multicolumn{{{width}}}{{l}}{{\\emph{{{title}}}}} \\\\")
        out += body[at : at + len(df)]
        at += len(df)
    return "\n".join([lines[0], r"\toprule", *ruled, r"\midrule", *out, *lines[-2:]]) + "\n"


def _groups(columns: pd.MultiIndex, level: int) -> list[tuple[int, int]]:
    """The (first, last) column positions of each run of equal labels down to ``level``."""
    keys = [tuple(c[: level + 1]) for c in columns]
    out, start = [], 0
    for i in range(1, len(keys) + 1):
        if i == len(keys) or keys[i] != keys[start]:
            out.append((start, i - 1))
            start = i
    return out


def ours(cell) -> str:
    """A cell's number of ours as the .tex prints it: the mean over its finished seeds, 'k/N' raised where k of the
    N declared seeds finished; --- when none did."""
    if not cell.values:
        return MISSING
    partial = f"\\textsuperscript{{{cell.n}/{cell.expected}}}" if cell.n < cell.expected else ""
    return f"{cell.mean:.2f}{partial}"


def panels(table, cells) -> tuple[list[tuple[str | None, pd.DataFrame]], list[str]]:
    """The table's cells as panels of LaTeX strings and the column levels held constant (named in the caption).
    One panel per difficulty when each difficulty has several columns, else one panel; columns (difficulty, aux,
    metric) levels with more than one value (metric always), then ours and paper (ours alone for a table the paper
    does not have). The reference row (Dual-Attention as the paper proposes it) in bold, as the paper sets it."""
    from emml.report.aggregate import reference_row

    column_levels = levels(cells)
    per = len(column_levels["aux"]) * len(column_levels["metric"])
    split = len(column_levels["difficulty"]) > 1 and per > 1
    keep = [k for k in ("aux", "metric") if len(column_levels[k]) > 1 or k == "metric"]
    if len(column_levels["difficulty"]) > 1 and not split:
        keep.insert(0, "difficulty")
    held = [k for k in ("difficulty", "aux") if k not in keep and not (split and k == "difficulty")]
    constant = [level_label(k, column_levels[k][0]) for k in held]
    paper = any(c.paper is not None for c in cells)
    metric_labels = {v: k for k, v in table.metrics.items()}
    ref = reference_row(table)
    extra = {r.label for r in table.rows if r.extra}

    def head(c, k: str) -> str:
        if k == "metric":
            return tex_text(metric_labels.get(c.metric) or level_label("metric", c.metric))
        return tex_text(level_label(k, getattr(c, k)))

    def row(label: str) -> str:
        text = tex_text(f"{label} {EXTRA_MARK}" if label in extra else label)
        return f"\\textbf{{{text}}}" if label == ref else text

    groups = column_levels["difficulty"] if split else [None]
    out = []
    for difficulty in groups:
        data: dict[tuple, dict[str, str]] = {}
        for c in cells:
            if difficulty is not None and c.difficulty != difficulty:
                continue
            col = tuple(head(c, k) for k in keep)
            data.setdefault((*col, "ours"), {})[row(c.row)] = ours(c)
            if paper:
                data.setdefault((*col, "paper"), {})[row(c.row)] = tex_text(c.paper) if c.paper is not None else MISSING
        rows = [row(r) for r in dict.fromkeys(c.row for c in cells)]
        df = pd.DataFrame(data, index=rows)
        df.columns = pd.MultiIndex.from_tuples(df.columns) if df.columns.nlevels > 1 else df.columns
        title = tex_text(level_label("difficulty", difficulty)) if difficulty is not None else None
        out.append((title, df))
    return out, constant


def _estimate(e, signed: bool = False) -> str:
    """An aggregate's estimate: the value, its interval in brackets when resampling could move it; a minus sign,
    not a hyphen."""
    fmt = "{:+.2f}" if signed else "{:.2f}"
    shown = [fmt.format(v).replace("-", "$-$") for v in (e.value, e.lo, e.hi)]
    return f"{shown[0]} [{shown[1]}, {shown[2]}]" if e.spread else shown[0]


def aggregate_panels(table, cells) -> dict[str, list[tuple[str | None, pd.DataFrame]]]:
    """emml/report/aggregate.py's comparisons, per metric (a float each: side by side, two metrics' intervals do not
    fit a page at 8 pt) as panels, one per setting (difficulty × aux), a row per row of the table with runs there:
    its IQM, the reference row minus the row and P(reference > row), each with its 95% interval (a number alone: no
    interval)."""
    from emml.report.aggregate import compare

    stats = ("IQM", r"$\Delta$", "P")
    out: dict[str, list] = {}
    found = compare(table, cells)
    for key in dict.fromkeys((c.metric, c.difficulty, c.aux) for c in found):
        data: dict[str, dict[str, str]] = {s: {} for s in stats}
        for c in found:
            if (c.metric, c.difficulty, c.aux) == key:
                label = tex_text(c.row)
                data["IQM"][label] = _estimate(c.iqm)
                data[stats[1]][label] = _estimate(c.difference, signed=True) if c.difference else ""
                data["P"][label] = _estimate(c.improvement) if c.improvement else ""
        title = tex_text(f"{level_label('difficulty', key[1])} · {level_label('aux', key[2])}")
        out.setdefault(key[0], []).append((title, pd.DataFrame(data).fillna("")))
    return out


def _float(caption: str, label: str, body: str, notes: str = "") -> list[str]:
    lines = [
        r"\begin{table*}[t]",
        r"\centering",
        r"\footnotesize",
        f"\\setlength{{\\tabcolsep}}{{{TABCOLSEP}}}",
        f"\\caption{{{caption}}}",
        f"\\label{{{label}}}",
        body.rstrip(),
    ]
    if notes:
        lines += [r"\par\smallskip", "{\\raggedright Notes: " + notes + "\\par}"]
    return [*lines, r"\end{table*}", ""]


def tex_table(plan, cells, results: pd.DataFrame, devs) -> str:
    """reports/<table>-<profile>.tex: the table and its aggregate as `table*` floats that compile unscaled in a
    minimal two-column document with the packages of the first line; a short caption, the deviations as notes."""
    from emml.experiments.table_files import list_tables
    from emml.report.aggregate import reference_row

    table, profile = plan.table, plan.profile.name  # the report's plan (emml/report/plan.py)
    parts, constant = panels(table, cells)
    used = results[results["run_name"].isin(plan.names)] if not results.empty else results
    paper = table.name in list_tables()
    what = f"Ours vs the paper's Table {table.name.removeprefix('table')}" if paper else table.title
    if used.empty:
        runs = "no finished run yet"
    else:
        lo, hi = int(used["frames"].min()), int(used["frames"].max())
        frames = f"{lo:,}" if lo == hi else f"{lo:,}--{hi:,}"
        seeds = ", ".join(str(s) for s in sorted(int(x) for x in used["seed"].unique()))
        runs = f"{frames} frames, seeds {seeds}, {len(used)} of {len(plan.names)} runs"
    setting = f" {', '.join(constant)}." if constant else ""
    cap = f"{tex_text(what)} ({tex_text(profile)} profile: {runs}).{tex_text(setting)} Ours: the mean over seeds"
    cap += r" (\textsuperscript{k/N}: k of N seeds finished); --- = not run."
    notes = []
    if devs is not None and devs.deviations:
        notes.append("Deviations from the paper: " + "; ".join(f"{line} [{h}]" for line, h in devs.deviations) + ".")
    if profile != "paper":
        notes.append(f"The '{profile}' profile is not the paper's protocol: compare orderings, not absolute numbers.")
    label = f"tab:ours-{table.name}-{profile}"
    lines = [
        f"% {table.name} [{profile}], written by `make reports` (emml/report/tex.py). Needs "
        + ", ".join(f"\\usepackage{{{p}}}" for p in TEX_PACKAGES)
        + "; table* floats, unscaled, within a two-column page's \\textwidth.",
        *_float(cap, label, tabular(parts, tex_text(table.row_header)), tex_text(" ".join(notes))),
    ]
    agg = aggregate_panels(table, cells) if table.transfer is None and any(c.values for c in cells) else {}
    names = {v: k for k, v in table.metrics.items()}
    ref = tex_text(reference_row(table) or "the reference row")
    for metric, parts in agg.items():
        agg_cap = (
            f"Aggregate per setting, {tex_text(names.get(metric, metric))} ({tex_text(what)}, {tex_text(profile)}): "
            f"IQM over a row's runs; $\\Delta$ = {ref} minus the row; P = P({ref} $>$ row); each with its 95\\% "
            "bootstrap interval, a number alone: one run, no interval."
        )
        lines += _float(agg_cap, f"{label}-aggregate-{metric}", tabular(parts, tex_text(table.row_header)))
    return "\n".join(lines)
