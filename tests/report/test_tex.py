"""The .tex a paper prints (issue 63) on a FIXTURE of made-up results and run dirs in tmp_path (never results): laid
out as the paper lays its tables out, unscaled, within a two-column page, Type 1 fonts only."""

import re
import shutil
import subprocess

import pandas as pd
import pytest

from emml.experiments.tables import load_table
from emml.report import deviations
from emml.report.cells import build_cells, paper_numbers, table_results
from emml.report.plan import plan_report
from emml.report.tables import shown_runs
from emml.report.tex import TEX_PACKAGES, tabular, tex_table, tex_text
from tests.report.test_tables import PROFILE, fake_results, fake_run_dirs

TWO_COLUMNS = (
    "\\pdfobjcompresslevel=0\n"  # the fonts' dictionaries readable in the PDF's bytes
    "\\documentclass[twocolumn,10pt]{article}\n"
    "\\setlength{\\textwidth}{7in}\\setlength{\\columnsep}{0.4in}\\setlength{\\oddsidemargin}{-0.25in}\n"
)
"""A two-column page: 7 in of text (505.9 pt), columns of 3.3 in, a 10 pt class (\\footnotesize: 8 pt)."""


def written(table: str, tmp_path, drop: tuple[str, ...] = ()) -> str:
    """The .tex of ``table`` [quick] on the fixture, every declared run finished but ``drop``."""
    t = load_table(table)
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


def test_table2_is_set_as_the_paper_sets_it_easy_and_hard_as_two_panels(tmp_path):
    tex = written("table2", tmp_path)
    assert tex.isascii() and "\\resizebox" not in tex and "graphicx" not in tex
    assert tex.count("\\begin{table*}") == tex.count("\\footnotesize") == 3  # the table, its aggregate per metric
    table, sgn, eqa = tex.split("\\end{table*}")[:3]
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
    # paper's numbers as printed
    assert body[easy + 7] == "\\textbf{Dual-Attention} & 0.20 & 0.86 & 0.20 & 0.53 & 0.30 & 0.96 & 0.30 & 0.58 \\\\"
    assert body[hard + 1] == "Text only & 0.20 & 0.2 & 0.20 & 0.33 & 0.20 & 0.2 & 0.20 & 0.33 \\\\"
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


@pytest.mark.skipif(shutil.which("pdflatex") is None, reason="no TeX engine (pdflatex) installed")
@pytest.mark.parametrize("table", ["table2", "table3", "table4", "experiments/eqa_gate"])
def test_each_table_compiles_unscaled_across_a_two_column_page_in_type1_fonts(table, tmp_path):
    tex = tmp_path / "table.tex"
    tex.write_text(written(table, tmp_path))
    packages = "".join(f"\\usepackage{{{p}}}\n" for p in TEX_PACKAGES)
    doc = tmp_path / "doc.tex"
    doc.write_text(f"{TWO_COLUMNS}{packages}\\begin{{document}}\n\\input{{{tex.as_posix()}}}\n\\end{{document}}\n")
    run = subprocess.run(
        ["pdflatex", "-interaction=nonstopmode", "-halt-on-error", doc.name],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    log = (tmp_path / "doc.log").read_text(errors="replace")
    assert run.returncode == 0, log[-2000:]
    assert "Overfull \\hbox" not in log, re.findall(r"Overfull \\hbox.*", log)  # wider than the page's text
    fonts = set(re.findall(rb"/Subtype\s*/(\w+)", (tmp_path / "doc.pdf").read_bytes())) & {b"Type1", b"Type3"}
    assert fonts == {b"Type1"}  # no Type 3 bitmap glyph
