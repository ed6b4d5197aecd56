"""Every relative link of every page `make reports` writes resolves (issue 63: the claims page linked
table5-quick.md, which is not written while Table 5 has no run), on a FIXTURE of made-up results and run dirs in
tmp_path (never results): a link names a file that lies beside the page, and an anchor one that the target page
declares."""

import re
from pathlib import Path

from emml.report.index import write_reports
from tests.report.test_efficiency import write_curves
from tests.report.test_tables import fake_results, fake_run_dirs

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def broken_links(folder: Path) -> list[str]:
    """'page: target' for each relative link of a Markdown page under ``folder`` whose file is not there, or whose
    anchor the target page does not declare (an `<a id>` or a heading's id)."""
    out = []
    for page in sorted(folder.rglob("*.md")):
        for target in LINK.findall(page.read_text()):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # https:, mailto:
                continue
            file, _, anchor = target.partition("#")
            path = (page.parent / file) if file else page
            if not path.is_file():
                out.append(f"{page.name}: {target}")
            elif anchor and path.suffix == ".md" and f'id="{anchor}"' not in path.read_text():
                out.append(f"{page.name}: {target} (no anchor)")
    return out


def test_every_relative_link_of_every_page_resolves(tracking, tmp_path):
    for table in ("table2", "table3"):  # no Table 4 or 5 run: their claims must not link pages never written
        fake_results(table, tmp_path / "results")
        fake_run_dirs(table, tmp_path / "runs")
        write_curves(tmp_path / "runs", table, lambda s: 0.5)
    out = tmp_path / "reports"
    write_reports(out, results_root=tmp_path / "results", run_root=tmp_path / "runs", log=lambda _: None)
    pages = {p.name for p in out.glob("*.md")}
    assert {"index.md", "claims-quick.md", "claims-quick-detail.md", "table2-quick.md"} <= pages
    assert not (out / "table5-quick.md").exists()
    links = sum(len(LINK.findall(p.read_text())) for p in out.glob("*.md"))
    assert links > 50
    assert broken_links(out) == []


def test_a_broken_link_is_found(tmp_path):
    (tmp_path / "a.md").write_text("[b](b.md) [c](c.md) [x](b.md#x) [y](b.md#y) ![f](f.png) [w](https://x.org)\n")
    (tmp_path / "b.md").write_text('<a id="x"></a>\n')
    assert broken_links(tmp_path) == ["a.md: c.md", "a.md: b.md#y (no anchor)", "a.md: f.png"]
