"""The .tex a paper prints (issues 63, 84) on a FIXTURE of made-up results and run dirs in tmp_path (never results):
laid out as the paper lays its tables out, unscaled, in one column where it fits and across both where not, Type 1
fonts only; one number of decimals per column, captions that name seeds and runs apart, every mark explained, no
quote LaTeX turns around."""

import re
import shutil
import subprocess

import pandas as pd
import pytest

from emml.config.profiles import profile_seeds
from emml.experiments.tables import load_table
from emml.report import deviations
from emml.report.cells import build_cells, paper_numbers, table_results
from emml.report.plan import plan_report
from emml.report.tables import shown_runs
from emml.report.tex import (
    COLUMN_PT,
    TEX_PACKAGES,
    decimals,
    padded,
    seed_list,
    tabular,
    tabular_width,
    tex_table,
    tex_text,
    text_width,
)
from emml.runs.naming import run_name
from tests.report.test_tables import PROFILE, fake_results, fake_run_dirs

TWO_COLUMNS = (
    "\\pdfobjcompresslevel=0\n"  # the fonts' dictionaries readable in the PDF's bytes
    "\\documentclass[twocolumn]{article}\n"
)
"""A bare two-column article: 10 pt (\\footnotesize: 8 pt), letter, columns of 229.5 pt, a \\textwidth of 469 pt."""
CASES = {
    "table2": ("table2", {}),
    "table2-seed0": ("table2", {"seeds": (0,)}),
    "table3-run-missing": ("table3", {"drop": ("da_no_sa-easy-aux-s1-quick",)}),
    "table4": ("table4", {}),
    "eqa_gate": ("experiments/eqa_gate", {}),
}
"""What the tests write (`written`'s arguments): panels (Table 2), its aggregates narrow enough for a column (one
run a cell: no interval), one panel with a cell's seeds missing (3), a transfer table with rows of ours and no
aggregate (4), an experiment without the paper's numbers and long row labels."""
NO_TEX = shutil.which("pdflatex") is None


def written(table: str, tmp_path, drop: tuple[str, ...] = (), seeds: tuple[int, ...] | None = None) -> str:
    """The .tex of ``table`` [quick] on the fixture, every declared run finished but ``drop`` and, with ``seeds``,
    those of other seeds."""
    t = load_table(table)
    if seeds is not None:
        specs = t.runs(profile_seeds(PROFILE), PROFILE)
        drop = (*drop, *(run_name(s.to_config(PROFILE)) for s in specs if s.seed not in seeds))
    results_root = tmp_path / "results"
    fake_results(table, tmp_path / "staged", drop=drop)  # under the table's name, as a path for an experiment
    results_root.mkdir()
    (tmp_path / "staged" / table).rename(results_root / t.name)
    fake_run_dirs(table, tmp_path / "runs")
    plan = plan_report(t, PROFILE, results_root, tmp_path / "runs")
    results = table_results(t, plan.profile, results_root)
    cells = build_cells(plan, results, paper_numbers(t.name))
    runs = shown_runs(plan, cells, results)
    devs = deviations.summarise(runs, deviations.noaux_schedule(plan))
    return tex_table(plan, cells, results, devs)


def floats(tex: str) -> list[str]:
    """Each float of a .tex, `table` or `table*`, from its \\begin to its \\end."""
    return [m.group(0) for m in re.finditer(r"\\begin\{(table\*?)\}.*?\\end\{\1\}", tex, re.S)]


def rows(float_: str) -> list[list[str]]:
    """The body rows of a float's tabular (between \\midrule and \\bottomrule), each as its cells; no panel title."""
    body = float_[float_.index("\\midrule") : float_.index("\\bottomrule")].split("\n")
    return [
        [c.strip() for c in line.removesuffix("\\\\").split(" & ")]
        for line in body
        if line.endswith("\\\\") and not line.startswith("\\multicolumn")
    ]


def case(name: str, tmp_path) -> str:
    """The .tex of one of `CASES`."""
    table, kw = CASES[name]
    return written(table, tmp_path, **kw)


def caption(float_: str) -> str:
    """A float's caption, without \\caption{}."""
    return re.search(r"\\caption\{(.*)\}\n\\label", float_).group(1)


def test_table2_is_set_as_the_paper_sets_it_easy_and_hard_as_two_panels(tmp_path):
    tex = written("table2", tmp_path)
    assert tex.isascii() and "\\resizebox" not in tex and "graphicx" not in tex
    assert tex.count("\\footnotesize") == 3  # the table, its aggregate per metric
    table, sgn, eqa = floats(tex)
    header = table[table.index("\\toprule") : table.index("\\midrule")].split("\n")
    assert header[1] == " & \\multicolumn{4}{c}{No Aux} & \\multicolumn{4}{c}{Aux} \\\\"
    assert header[2] == "\\cmidrule(lr){2-5} \\cmidrule(lr){6-9}"  # under each group header
    assert header[4] == " ".join(f"\\cmidrule(lr){{{a}-{a + 1}}}" for a in (2, 4, 6, 8))
    assert header[5] == "Model & ours & paper & ours & paper & ours & paper & ours & paper \\\\"
    body = table[table.index("\\midrule") :].split("\n")
    easy, hard = (
        body.index("\\multicolumn{9}{l}{\\emph{Easy}} \\\\"),
        body.index("\\multicolumn{9}{l}{\\emph{Hard}} \\\\"),
    )
    assert hard - easy == 9 and body[hard - 1] == "\\midrule"  # seven rows each, Easy first
    # the fixture's runs score 0.1 × (seed + 1): the mean of three seeds is 0.20 (of Easy · Aux's five, 0.30); the
    # paper's numbers to two decimals (it prints Text only's SGN as 0.2)
    assert body[easy + 7] == "\\textbf{Dual-Attention} & 0.20 & 0.86 & 0.20 & 0.53 & 0.30 & 0.96 & 0.30 & 0.58 \\\\"
    assert body[hard + 1] == "Text only & 0.20 & 0.20 & 0.20 & 0.33 & 0.20 & 0.20 & 0.20 & 0.33 \\\\"
    for aggregate, metric in ((sgn, "sgn_test"), (eqa, "eqa_test")):
        assert f"\\label{{tab:ours-table2-quick-aggregate-{metric}}}" in aggregate
        assert "Model & IQM & $\\Delta$ & P \\\\" in aggregate
        assert aggregate.count("\\emph{") == 4 and "\\emph{Hard $\\cdot$ No Aux}" in aggregate  # a panel per setting
    line = next(x for x in sgn.split("\n") if x.startswith("GA &"))  # Easy, No Aux: 0.5 vs 0.1 / 0.2 / 0.3
    assert re.fullmatch(
        r"GA & 0\.20 \[0\.\d\d, 0\.\d\d\] & \+0\.00 \[\$-\$0\.\d\d, \+0\.\d\d\] & 0\.50 \[.*\] \\\\", line
    ), line


def test_a_cell_with_seeds_missing_says_how_many_finished(tmp_path):
    tex = written("table3", tmp_path, drop=("da_no_sa-easy-aux-s1-quick",))
    line = next(x for x in tex.split("\n") if x.startswith("w/o SA &"))
    assert line.split(" & ")[5] == "0.20\\textsuperscript{2/3}"  # Aux SGN, seeds 0 and 2: 0.1 and 0.3
    assert "Sec.~5.1" in tex and "\\S" not in tex  # \S: a glyph of a font that needs cm-super


def test_tabular_rules_each_group_and_titles_each_panel():
    columns = pd.MultiIndex.from_tuples([("A", "x"), ("A", "y"), ("B", "x"), ("C", "x"), ("C", "y")])
    one = pd.DataFrame([["1", "2", "3", "4", "5"]], index=["r"], columns=columns)
    text = tabular([("P", one), ("Q", one.rename(index={"r": "s"}))], stub="Row")
    lines = text.split("\n")
    assert lines[:6] == [
        "\\begin{tabular}{lccccc}",
        "\\toprule",
        " & \\multicolumn{2}{c}{A} & B & \\multicolumn{2}{c}{C} \\\\",
        "\\cmidrule(lr){2-3} \\cmidrule(lr){5-6}",  # none under B: one column
        "Row & x & y & x & x & y \\\\",
        "\\midrule",
    ]
    assert lines[6:11] == [
        "\\multicolumn{6}{l}{\\emph{P}} \\\\",
        "r & 1 & 2 & 3 & 4 & 5 \\\\",
        "\\midrule",
        "\\multicolumn{6}{l}{\\emph{Q}} \\\\",
        "s & 1 & 2 & 3 & 4 & 5 \\\\",
    ]


def test_tex_text_sets_in_type1_glyphs_only():
    assert tex_text("§5.1: 1 < 2 > 0, a_b · c ☃") == "Sec.~5.1: 1 $<$ 2 $>$ 0, a\\_b $\\cdot$ c "


def test_tex_text_quotes_a_phrase_as_latex_does_and_keeps_apostrophes():
    # a bare ' before a phrase prints as a closing quote (the issue's ’quick’)
    assert tex_text("App. 'Baseline details': the runs' ('a' or 'b_c')") == (
        "App. `Baseline details': the runs' (`a' or `b\\_c')"
    )


def test_each_paper_column_has_one_number_of_decimals(tmp_path):
    main = floats(written("table2", tmp_path))[0]
    head = main[: main.index("\\midrule")].split("\n")[-2].removesuffix(" \\\\").split(" & ")
    assert head.count("paper") == head.count("ours") == 4
    body = rows(main)
    for j, kind in enumerate(head[1:], start=1):
        numbers = [r[j].split("\\textsuperscript")[0] for r in body if r[j] != "---"]
        assert {decimals(n) for n in numbers} == {2}, (kind, numbers)  # the paper prints Text only's SGN as 0.2
    assert "the paper's numbers to 2 decimals (0.2 written 0.20)" in caption(main)
    assert "written" not in caption(floats(written("table3", tmp_path / "t3"))[0])  # none of Table 3's padded


def test_a_paper_number_is_padded_never_rounded():
    assert padded("0.2", 2) == "0.20" and padded("1", 2) == "1.00" and padded("0.33", 2) == "0.33"
    assert decimals("0.2") == 1 and decimals("0.20") == 2 and decimals("7") == 0
    with pytest.raises(ValueError, match="'0.125' has more than 2 decimals"):
        padded("0.125", 2)
    with pytest.raises(ValueError, match="paper number must be a decimal number.*'n/a'"):
        decimals("n/a")


def test_seed_list_writes_a_run_of_three_or_more_seeds_as_a_range():
    assert seed_list([2, 0, 1]) == "0--2"
    assert seed_list([0, 1, 2, 5, 7, 8, 9, 11]) == "0--2, 5, 7--9, 11"
    assert seed_list([0, 1]) == "0, 1" and seed_list([3, 3]) == "3"


def test_the_caption_names_the_seeds_apart_from_the_runs_finished(tmp_path):
    cap = caption(floats(written("table3", tmp_path, drop=("da_no_sa-easy-aux-s1-quick",)))[0])
    found = re.search(
        r"\(\\texttt\{quick\} profile: 1,500,000 frames, seeds ([^;)]*); (\d+) of (\d+) runs finished\)", cap
    )
    assert found, cap  # not 'seeds 0, 1, 2, 49 of 50 runs', a seed 49
    assert found.group(1) == "0--4" and int(found.group(2)) == int(found.group(3)) - 1 > 0
    assert "Setting: Easy." in cap


MARKS = {
    "$\\dagger$": "$\\dagger$: a test instruction of ours",
    "\\textsuperscript{": "\\textsuperscript{k/N}: k of the cell's N seeds finished",
    "\\textbf{": "bold: the paper's model",
    "---": "---: ",
}
"""A mark a table's cells may use, and how its caption explains it."""


@pytest.mark.parametrize("name", CASES)
def test_the_caption_explains_every_mark_the_table_uses_and_no_other(name, tmp_path):
    main = floats(case(name, tmp_path))[0]
    body, cap = main[main.index("\\midrule") : main.index("\\bottomrule")], caption(main)
    used = {mark for mark in MARKS if mark in body}
    assert used == {mark for mark, key in MARKS.items() if key in cap}, cap
    if name == "table4":  # rows of ours (dagger), cells with no run (the fixture has no transfer scores) and no
        assert used == {"$\\dagger$", "---"}  # number in the paper
        assert "---: no finished run (ours) or no number in the paper (paper)" in cap
    if name == "table3-run-missing":
        assert used == {"\\textsuperscript{", "\\textbf{"}


@pytest.mark.parametrize("name", CASES)
def test_no_quote_is_set_the_wrong_way_round(name, tmp_path):
    tex = case(name, tmp_path)
    assert not re.findall(r"(?:^|[\s(\[{])'.{0,20}", tex, re.M)  # LaTeX sets an opening ' as a closing quote
    assert "The \\texttt{quick} profile is not the paper's protocol" in tex


@pytest.mark.parametrize(
    ("name", "kinds"),
    [
        ("table2-seed0", ["table*", "table", "table"]),  # a run a cell: the aggregates (no interval) fit a column
        ("table2", ["table*", "table*", "table*"]),  # three seeds: an interval in every cell, ~283 pt
    ],
)
def test_a_tabular_that_fits_a_column_is_a_one_column_float(name, kinds, tmp_path):
    tex = case(name, tmp_path)
    assert [re.match(r"\\begin\{(table\*?)\}", f).group(1) for f in floats(tex)] == kinds  # the panels: 9 columns
    for f, kind in zip(floats(tex), kinds, strict=True):
        (body,) = tabulars(f)
        assert (kind == "table") == (tabular_width(body) <= COLUMN_PT / 1.02), (kind, tabular_width(body))
        assert f.endswith(f"\\end{{{kind}}}")
    aggregate = caption(floats(tex)[1])
    assert "interval in brackets" in aggregate and "blank on Dual-Attention's own row" in aggregate
    assert tex.split("\n")[0].endswith(
        f"a table float fits a two-column article's column ({COLUMN_PT} pt), a table* its \\textwidth."
    )


def test_tabular_width_sums_each_columns_widest_cell_and_its_space():
    text = "\\begin{tabular}{lc}\n\\toprule\nab & 0.20 \\\\\n\\midrule\nx & 1 \\\\\n\\bottomrule\n\\end{tabular}"
    assert tabular_width(text) == pytest.approx((4.25 + 4.722) + (3 * 4.25 + 2.361) + 2 * 8)  # tabcolsep 4pt a side
    title = "\\multicolumn{2}{l}{\\emph{" + "m" * 20 + "}} \\\\"
    wide = text.replace("\\midrule\n", f"\\midrule\n{title}\n")
    assert tabular_width(wide) == pytest.approx(20 * 7.083 * 1.12 + 8)  # a title wider than both widens the last
    assert text_width("\\textbf{ab}") == pytest.approx(1.23 * (4.25 + 4.722))
    assert text_width("$-$0.18\\textsuperscript{2/3}") == pytest.approx(6.611 + 3 * 4.25 + 2.361 + 0.91 * 3 * 4.25)
    with pytest.raises(ValueError, match="not a tabular"):
        tabular_width("\\begin{tabular}{p{3cm}}\n\\end{tabular}")


def tabulars(tex: str) -> list[str]:
    return re.findall(r"\\begin\{tabular\}.*?\\end\{tabular\}", tex, re.S)


def pdflatex(doc: str, folder) -> tuple[subprocess.CompletedProcess, str]:
    """Compile ``doc`` in ``folder``: the run and its log."""
    (folder / "doc.tex").write_text(doc)
    run = subprocess.run(
        ["pdflatex", "-interaction=nonstopmode", "-halt-on-error", "doc.tex"],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=120,
    )
    return run, (folder / "doc.log").read_text(errors="replace")


@pytest.mark.skipif(NO_TEX, reason="no TeX engine (pdflatex) installed")
def test_tabular_width_is_within_two_percent_of_what_pdflatex_sets(tmp_path):
    found = [t for k, name in enumerate(CASES) for t in tabulars(case(name, tmp_path / str(k)))]
    packages = "".join(f"\\usepackage{{{p}}}\n" for p in TEX_PACKAGES)
    measure = "".join(
        f"\\sbox\\tab{{\\footnotesize\\setlength{{\\tabcolsep}}{{4pt}}{t}}}\\typeout{{WIDTH {k} \\the\\wd\\tab}}\n"
        for k, t in enumerate(found)
    )
    run, log = pdflatex(
        f"{TWO_COLUMNS}{packages}\\newsavebox\\tab\n\\begin{{document}}\n{measure}x\\end{{document}}\n", tmp_path
    )
    assert run.returncode == 0, log[-2000:]
    measured = [float(w) for w in re.findall(r"^WIDTH \d+ ([\d.]+)pt$", run.stdout, re.M)]
    assert len(measured) == len(found) >= 8
    for t, width in zip(found, measured, strict=True):
        assert abs(tabular_width(t) / width - 1) < 0.02, (width, tabular_width(t), t[:300])


@pytest.mark.skipif(NO_TEX, reason="no TeX engine (pdflatex) installed")
@pytest.mark.parametrize("name", CASES)
def test_each_table_compiles_unscaled_in_a_two_column_article_in_type1_fonts(name, tmp_path):
    tex = tmp_path / "table.tex"
    tex.write_text(case(name, tmp_path))
    packages = "".join(f"\\usepackage{{{p}}}\n" for p in TEX_PACKAGES)
    run, log = pdflatex(
        f"{TWO_COLUMNS}{packages}\\begin{{document}}\n\\input{{{tex.as_posix()}}}\n\\end{{document}}\n", tmp_path
    )
    assert run.returncode == 0, log[-2000:]
    # wider than its column (a table float) or the page's text (table*)
    assert "Overfull \\hbox" not in log, re.findall(r"Overfull \\hbox.*", log)
    fonts = set(re.findall(rb"/Subtype\s*/(\w+)", (tmp_path / "doc.pdf").read_bytes())) & {b"Type1", b"Type3"}
    assert fonts == {b"Type1"}  # no Type 3 bitmap glyph
