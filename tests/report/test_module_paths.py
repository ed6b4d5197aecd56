"""No stale module path in what the reports print (issue 64: `emml/fidelity.py` and `emml/transfer.py` were still
written into the committed pages after the modules moved to emml/experiments/ and emml/eval/): every `emml/….py`
named in a committed page of reports/, or in a string of the code that writes them (emml/report/, and the claims
the pages quote, emml/experiments/claims/), is a file of this checkout."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MODULE_PATH = re.compile(r"\bemml/[A-Za-z0-9_/]+\.py\b")


def stale_paths(files) -> list[str]:
    """'file: emml/x.py' for each `emml/….py` named in ``files`` that does not exist under the checkout."""
    out = []
    for file in files:
        for path in sorted(set(MODULE_PATH.findall(file.read_text(errors="replace")))):
            if not (ROOT / path).is_file():
                out.append(f"{file.relative_to(ROOT)}: {path}")
    return out


def test_the_committed_reports_name_only_modules_that_exist():
    pages = sorted((ROOT / "reports").glob("*.md")) + sorted((ROOT / "reports").glob("*.tex"))
    assert pages, "no committed report pages found"
    assert stale_paths(pages) == []


def test_the_report_code_names_only_modules_that_exist():
    code = sorted((ROOT / "emml" / "report").glob("*.py")) + sorted((ROOT / "emml/experiments/claims").glob("*.py"))
    assert stale_paths(code) == []


def test_a_stale_path_is_found(tmp_path, monkeypatch):
    page = ROOT / "reports" / "index.md"
    monkeypatch.setattr(Path, "read_text", lambda self, **_: "see `emml/fidelity.py` and emml/report/tables.py")
    assert stale_paths([page]) == ["reports/index.md: emml/fidelity.py"]
