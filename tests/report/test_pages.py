"""The table pages a reader takes in at a glance (issue 49) on a FIXTURE of made-up results and run dirs in tmp_path
(never results): a headline and the figures first, the rliable figures written with TrueType fonts, `.tex` that a
minimal document compiles within the text width, and `emml reports` twice the same bytes."""

import shutil
import subprocess

import pytest

from emml.report.index import write_reports
from emml.report.tables import TEX_PACKAGES, report_table
from tests.report.test_efficiency import write_curves
from tests.report.test_tables import PROFILE, fake_results, fake_run_dirs


def pages(tmp_path, tables=("table2", "table3")) -> list[dict]:
    for table in tables:
        fake_results(table, tmp_path / "results")
        fake_run_dirs(table, tmp_path / "runs")
        write_curves(tmp_path / "runs", table, lambda s: 0.5)
    kw = dict(results_root=tmp_path / "results", out=tmp_path / "reports", run_root=tmp_path / "runs")
    return [report_table(table, PROFILE, **kw) for table in tables]


def test_a_page_opens_with_its_headline_and_figures_and_lists_the_crossings(tmp_path):
    (data,) = pages(tmp_path, ("table3",))
    text = (tmp_path / "reports" / "table3-quick.md").read_text()
    head = text.split("\n")
    assert head[2].startswith("**In one line** (quick; 3 seeds per cell): Easy · No Aux: SGN test DA Multi-Task")
    assert "![table3-quick-rliable](table3-quick-rliable.png)" in text[: text.index("Ours vs the paper")]
    assert "### Sample efficiency" in text and "0.75M / 0.75M / 0.75M" in text  # 0.5 of 1.5M frames
    pdf = (tmp_path / "reports" / "table3-quick-rliable.pdf").read_bytes()
    assert b"/Type3" not in pdf and b"/CIDFontType2" in pdf  # TrueType (Type 42): emml/report/emml.mplstyle
    assert {p.rsplit("/", 1)[1] for p in data["paths"]} >= {"table3-quick-rliable.png", "table3-quick-rliable.pdf"}


def test_the_tex_states_its_packages_is_plain_ascii_and_scales_to_the_width(tmp_path):
    pages(tmp_path)
    for table in ("table2", "table3"):
        tex = (tmp_path / "reports" / f"{table}-quick.tex").read_text()
        first = tex.split("\n")[0]
        assert first.startswith("%") and all(f"\\usepackage{{{p}}}" in first for p in TEX_PACKAGES)
        assert tex.isascii()
        assert tex.count("\\resizebox{\\ifdim\\width>\\linewidth") == tex.count("\\begin{tabular}") == 2
        caption = tex[tex.index("\\caption{") :].split("\n")[0]
        assert len(caption) < 300 and "emml run" not in caption  # a short caption; the deviations go to the notes
        assert "Notes: Deviations from the paper" in tex


@pytest.mark.skipif(shutil.which("pdflatex") is None, reason="no TeX engine (pdflatex) installed")
def test_each_generated_tex_compiles_in_a_minimal_document_within_the_text_width(tmp_path):
    pages(tmp_path)
    for table in ("table2", "table3"):
        doc = tmp_path / f"doc-{table}.tex"
        packages = "".join(f"\\usepackage{{{p}}}\n" for p in TEX_PACKAGES)
        path = (tmp_path / "reports" / f"{table}-quick.tex").as_posix()
        doc.write_text(
            f"\\documentclass{{article}}\n{packages}\\begin{{document}}\n\\input{{{path}}}\n\\end{{document}}\n"
        )
        run = subprocess.run(
            ["pdflatex", "-interaction=nonstopmode", "-halt-on-error", doc.name],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=120,
        )
        log = (tmp_path / f"doc-{table}.log").read_text(errors="replace")
        assert run.returncode == 0, log[-2000:]
        assert "Overfull \\hbox" not in log  # wider than \textwidth


def test_emml_reports_twice_changes_no_byte(tracking, tmp_path):
    for table in ("table2", "table3"):
        fake_results(table, tmp_path / "results")
        fake_run_dirs(table, tmp_path / "runs")
        write_curves(tmp_path / "runs", table, lambda s: 0.5)
    kw = dict(results_root=tmp_path / "results", run_root=tmp_path / "runs", log=lambda _: None)
    write_reports(tmp_path / "reports", **kw)
    first = {p.name: p.read_bytes() for p in sorted((tmp_path / "reports").iterdir())}
    assert {"index.md", "claims-quick.md", "table2-quick-rliable.pdf", "table3-quick-curves.png"} <= set(first)
    write_reports(tmp_path / "reports", **kw)
    assert {p.name: p.read_bytes() for p in sorted((tmp_path / "reports").iterdir())} == first
