"""reports/<table>-<profile>.tex: a table's report as floats a two-column paper prints as they are (issue 63).

Laid out as the paper lays its tables out: its rows are rows; a table whose difficulties each hold several columns
(Table 2: Easy and Hard × No Aux and Aux × SGN and EQA) is set as one panel per difficulty, stacked, so that no row
needs the width of both; each metric's column holds ours (the mean over the finished seeds; the seeds themselves are
on the Markdown page) beside the paper's number. Every tabular is set in \\footnotesize (8 pt under a 10 pt class),
unscaled (no \\resizebox), in a `table` float when its width (estimated here from the fonts' metrics,
`tabular_width`) fits one column of a two-column article, else a `table*` across both. The aggregate is its own
float per metric, a panel per setting. Every number of a column has the same decimals (the paper's `0.2` is written
`0.20`); the caption names the profile, the seeds and the runs finished apart and explains every mark the table uses.
\\cmidrule under every group header; ASCII only, and only glyphs of the fonts a bare pdflatex embeds as Type 1 (no
\\S: 'Sec.'; no straight quote, which Computer Modern lacks: a quoted phrase as LaTeX's `...', a profile's name in
\\texttt). The tabulars are pandas' Styler's; this module adds the panels, rules and float.
"""

from __future__ import annotations

import re
from decimal import Decimal, InvalidOperation

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
COLUMN_PT = 229.5
r"""One column of `\documentclass[twocolumn]{article}` (10 pt, letter): a tabular at most this wide (estimated) is
set in a one-column `table`, a wider one in a `table*` (that class's \textwidth: 469 pt)."""

FIT_MARGIN = 1.02
"""A tabular is set in one column when its estimate with this margin fits: `tabular_width` was within 1% of
pdflatex's width on every table of reports/ (kerning it ignores, styles it scales by their widest ratio)."""

_CMR8_PT = {
    2.361: "il.,;:'![]`",
    2.597: "fj",
    2.833: "- ~",
    3.061: "I",
    3.306: "t()",
    3.313: "r",
    3.353: "s",
    3.778: "cez",
    4.014: "?",
    4.25: "ago0123456789/*",
    4.364: "J",
    4.486: "kqvxy",
    4.722: "bdhnpuS",
    5.195: "Z",
    5.308: "L",
    5.545: "F",
    5.781: "EP",
    6.017: "B",
    6.139: "wCT",
    6.253: "R",
    6.367: "AHNUVXY",
    6.489: "D",
    6.603: "K",
    6.611: "OQ+=&@",
    6.668: "G",
    7.083: "m%#",
    7.783: "M",
    8.728: "W",
}
"""Widths in pt of Computer Modern Roman at 8 pt (cmr8.tfm; the space its interword space), by width."""
CHAR_PT = {ch: pt for pt, chars in _CMR8_PT.items() for ch in chars}
WIDE_PT = 8.728
"""A character not in `CHAR_PT` counts as the widest (W): the estimate errs toward a wider float."""
TOKEN_PT = {
    r"$-$": 6.611,
    r"$<$": 6.611,
    r"$>$": 6.611,
    r"$\times$": 6.611,
    r"$\leq$": 6.611,
    r"$\geq$": 6.611,
    r"$\Delta$": 7.083,
    r"$\dagger$": 3.778,
    r"$\cdot$": 2.361,
    r"$\mid$": 2.361,
    r"$\rightarrow$": 8.5,
    r"\_": 3.06,
    r"\dots{}": 11.334,
    r"\textbackslash{}": 4.25,
    r"\%": 7.083,
    r"\&": 6.611,
    r"\#": 7.083,
    r"\$": 4.25,
    r"\{": 4.25,
    r"\}": 4.25,
    "---": 8.5,
    "--": 4.25,
}
"""What `tex_text` and the tables write for a character cmr8 lacks, at 8 pt (measured with pdflatex)."""
STYLE_SCALE = {"textbf": 1.23, "emph": 1.12, "texttt": 1.0, "textsuperscript": 0.91}
r"""A styled span's width over the same text in cmr8: the largest ratio over letters and digits of cmbx8 (bold),
cmti8 (\emph); a superscript 'k/N' measured 11.5 pt (cmr6); cmtt8 is 4.2 pt a character, about cmr8's mean."""
_TOKEN = re.compile(r"\\(textbf|emph|texttt|textsuperscript)\{([^{}]*)\}|" + "|".join(map(re.escape, TOKEN_PT)))


def text_width(tex: str) -> float:
    """The width in pt of a cell's LaTeX (as this module writes it) set in \\footnotesize: cmr8's widths, the tokens
    of `TOKEN_PT`, a styled span scaled by `STYLE_SCALE`; kerning ignored."""
    width, at = 0.0, 0
    for m in _TOKEN.finditer(tex):
        width += sum(CHAR_PT.get(ch, WIDE_PT) for ch in tex[at : m.start()])
        width += text_width(m.group(2)) * STYLE_SCALE[m.group(1)] if m.group(1) else TOKEN_PT[m.group(0)]
        at = m.end()
    return width + sum(CHAR_PT.get(ch, WIDE_PT) for ch in tex[at:])


_MULTICOLUMN = re.compile(r"\\multicolumn\{(\d+)\}\{[lcr]\}\{(.*)\}")


def tabular_width(tex: str) -> float:
    """The natural width in pt of a tabular `tabular` writes, at \\footnotesize with `TABCOLSEP`: each column as wide
    as its widest cell (`text_width`) plus the space either side; a \\multicolumn wider than the columns it spans
    widens its last one, as LaTeX does."""
    sep = 2 * float(TABCOLSEP.removesuffix("pt"))
    lines = tex.strip().split("\n")
    spec = re.fullmatch(r"\\begin\{tabular\}\{([lcr]+)\}", lines[0])
    if spec is None:
        raise ValueError(f"tabular_width: not a tabular this module writes: {lines[0]!r}")
    widths = [0.0] * len(spec.group(1))
    spans = []
    for line in lines[1:-1]:
        if not line.endswith("\\\\"):
            continue  # a rule
        col = 0
        for cell in re.split(r"(?<!\\)&", line.removesuffix("\\\\")):
            cell = cell.strip()
            m = _MULTICOLUMN.fullmatch(cell)
            n, content = (int(m.group(1)), m.group(2)) if m else (1, cell)
            if n == 1:
                widths[col] = max(widths[col], text_width(content))
            else:
                spans.append((col, col + n - 1, text_width(content)))
            col += n
    for first, last, width in sorted(spans, key=lambda s: s[1] - s[0]):
        short = width - (sum(widths[first : last + 1]) + sep * (last - first))
        if short > 0:
            widths[last] += short
    return sum(widths) + sep * len(widths)


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


_QUOTED = re.compile(r"(?<![\w'])'([^'\n]+?)'(?!\w)")
"""A phrase in single quotes: its opening quote stands after no letter (an apostrophe does)."""


def tex_text(text: str) -> str:
    """Plain text as LaTeX that a minimal pdflatex document sets: specials escaped, a phrase in single quotes quoted
    as LaTeX quotes (`...': a bare ' opening it would print as a closing quote), the Unicode above replaced, any
    other non-ASCII character dropped."""
    out = _QUOTED.sub(r"`\1'", _tex_escape(text)).replace("|", r"$\mid$")
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


def decimals(number: str) -> int:
    """How many decimals a number is printed with ('0.2': 1, '0.20': 2, '1': 0); ValueError naming it if it is not a
    decimal number."""
    try:
        exponent = Decimal(number).as_tuple().exponent
    except InvalidOperation:
        raise ValueError(f"a paper number must be a decimal number as printed (e.g. 0.20), got {number!r}") from None
    if not isinstance(exponent, int):
        raise ValueError(f"a paper number must be finite, got {number!r}")
    return max(0, -exponent)


def padded(number: str, places: int) -> str:
    """``number`` as printed, zeros added to ``places`` decimals ('0.2', 2: '0.20'); never rounded: ValueError when it
    has more decimals than ``places``."""
    if decimals(number) > places:
        raise ValueError(f"padded: {number!r} has more than {places} decimals; it would be rounded")
    return f"{Decimal(number):.{places}f}"


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
    does not have), the paper's numbers each with as many decimals as the most any has (zeros added: 0.2 as 0.20).
    The reference row (Dual-Attention as the paper proposes it) in bold, as the paper sets it."""
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
    places = max((decimals(c.paper) for c in cells if c.paper is not None), default=0)  # the paper column's decimals

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
                number = padded(c.paper, places) if c.paper is not None else MISSING
                data.setdefault((*col, "paper"), {})[row(c.row)] = number
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


def seed_list(seeds) -> str:
    """Seeds as a caption names them: a run of three or more consecutive seeds as a range ('0--2, 5'; '0, 1')."""
    ordered = sorted(set(int(x) for x in seeds))
    runs: list[list[int]] = []
    for seed in ordered:
        if runs and seed == runs[-1][-1] + 1:
            runs[-1].append(seed)
        else:
            runs.append([seed])
    parts = [f"{r[0]}--{r[-1]}" if len(r) > 2 else ", ".join(map(str, r)) for r in runs]
    return ", ".join(parts)


def _float(caption: str, label: str, body: str, notes: str = "") -> list[str]:
    """A float of ``body`` (a tabular), `table` when it fits a column (`COLUMN_PT`), else `table*`."""
    env = "table" if tabular_width(body) * FIT_MARGIN <= COLUMN_PT else "table*"
    lines = [
        f"\\begin{{{env}}}[t]",
        r"\centering",
        r"\footnotesize",
        f"\\setlength{{\\tabcolsep}}{{{TABCOLSEP}}}",
        f"\\caption{{{caption}}}",
        f"\\label{{{label}}}",
        body.rstrip(),
    ]
    if notes:
        lines += [r"\par\smallskip", "{\\raggedright Notes: " + notes + "\\par}"]
    return [*lines, f"\\end{{{env}}}", ""]


def marks(table, cells) -> str:
    """The caption's key to the marks the table's cells use, each only where the table has it: ours (always), the
    k/N mark, ---, the paper's numbers padded to its decimals, the bold row, the dagger."""
    from emml.report.aggregate import reference_row

    shown_rows = {c.row for c in cells}
    out = ["Ours: the mean over the finished seeds"]
    if any(c.values and c.n < c.expected for c in cells):
        out.append(r"\textsuperscript{k/N}: k of the cell's N seeds finished")
    numbers = [c.paper for c in cells if c.paper is not None]
    missing = [
        *(["no finished run"] if any(not c.values for c in cells) else []),
        *(["no number in the paper"] if numbers and any(c.paper is None for c in cells) else []),
    ]
    if missing:
        out.append("---: " + " (ours) or ".join(missing) + (" (paper)" if len(missing) > 1 else ""))
    places = max(map(decimals, numbers), default=0)
    short = next((n for n in numbers if decimals(n) < places), None)
    if short is not None:
        out.append(f"the paper's numbers to {places} decimals ({short} written {padded(short, places)})")
    ref = reference_row(table)
    if ref in shown_rows:
        out.append(f"bold: the paper's model as it proposes it ({tex_text(ref)})")
    if any(r.extra and r.label in shown_rows for r in table.rows):
        out.append(r"$\dagger$: a test instruction of ours that the paper's table does not name")
    return "; ".join(out) + "."


def tex_table(plan, cells, results: pd.DataFrame, devs) -> str:
    """reports/<table>-<profile>.tex: the table and its aggregate as floats (`table` where one fits a column, else
    `table*`) that compile unscaled in a two-column article with the packages of the first line; a caption that
    names the profile, frames, seeds and runs finished and explains every mark; the deviations as notes."""
    from emml.experiments.table_files import list_tables
    from emml.report.aggregate import reference_row

    table, profile = plan.table, plan.profile.name  # the report's plan (emml/report/plan.py)
    parts, constant = panels(table, cells)
    used = results[results["run_name"].isin(plan.names)] if not results.empty else results
    paper = table.name in list_tables()
    what = f"Ours vs the paper's Table {table.name.removeprefix('table')}" if paper else table.title
    shown_profile = f"\\texttt{{{tex_text(profile)}}}"
    if used.empty:
        runs = f"none of {len(plan.names)} runs finished yet"
    else:
        lo, hi = int(used["frames"].min()), int(used["frames"].max())
        frames = f"{lo:,}" if lo == hi else f"{lo:,}--{hi:,}"
        runs = f"{frames} frames, seeds {seed_list(used['seed'])}; {len(used)} of {len(plan.names)} runs finished"
    setting = f" Setting: {tex_text(', '.join(constant))}." if constant else ""
    cap = f"{tex_text(what)} ({shown_profile} profile: {runs}).{setting} {marks(table, cells)}"
    notes = []
    if devs is not None and devs.deviations:
        listed = "; ".join(f"{line} [{held}]" for line, held in devs.deviations)
        notes.append(tex_text(f"Deviations from the paper: {listed}."))
    if profile != "paper":
        notes.append(
            f"The {shown_profile} profile is not the paper's protocol: compare orderings, not absolute numbers."
        )
    label = f"tab:ours-{table.name}-{profile}"
    lines = [
        f"% {table.name} [{profile}], written by `make reports` (emml/report/tex.py). Needs "
        + ", ".join(f"\\usepackage{{{p}}}" for p in TEX_PACKAGES)
        + f"; unscaled: a table float fits a two-column article's column ({COLUMN_PT} pt), a table* its \\textwidth.",
        *_float(cap, label, tabular(parts, tex_text(table.row_header)), " ".join(notes)),
    ]
    agg = aggregate_panels(table, cells) if table.transfer is None and any(c.values for c in cells) else {}
    names = {v: k for k, v in table.metrics.items()}
    ref = tex_text(reference_row(table) or "the reference row")
    for metric, parts in agg.items():
        agg_cap = (
            f"Aggregate per setting, {tex_text(names.get(metric, metric))} ({tex_text(what)}, {shown_profile} "
            f"profile): IQM over a row's runs; $\\Delta$ = {ref} minus the row; P = P({ref} $>$ row); each with its "
            f"95\\% bootstrap interval in brackets, a number alone: one run, no interval; $\\Delta$ and P blank on "
            f"{ref}'s own row."
        )
        lines += _float(agg_cap, f"{label}-aggregate-{metric}", tabular(parts, tex_text(table.row_header)))
    return "\n".join(lines)
