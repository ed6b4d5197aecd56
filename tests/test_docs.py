"""The docs site and the README (issue 63): `make docs` builds the site strictly (no broken link or anchor, no page
left out of the nav, the generated CLI and config references included), and the README fits a screen or two,
leads with the two commands CI runs, and links only what exists or what `make reports` writes."""

import importlib.util
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from emml.experiments.table_files import list_experiments

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MKDOCS = importlib.util.find_spec("mkdocs") is not None and importlib.util.find_spec("material") is not None


def _strict_build(folder):
    """`mkdocs build --strict` of the site copied into ``folder`` (the generated pages there), into folder/site."""
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(folder / "mkdocs.yml"), "-d", "site"],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=300,
        env={"NO_MKDOCS_2_WARNING": "1", "PATH": "/usr/bin:/bin", "HOME": str(folder)},
    )


@pytest.mark.skipif(not MKDOCS, reason="mkdocs or mkdocs-material not installed (the dev extra: pip install -e .[dev])")
def test_the_docs_site_builds_strictly_with_its_generated_references(tmp_path):
    shutil.copy(ROOT / "mkdocs.yml", tmp_path / "mkdocs.yml")
    shutil.copytree(ROOT / "docs", tmp_path / "docs", ignore=shutil.ignore_patterns("cli.md", "config.md"))
    gen = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "docs_reference.py"), str(tmp_path / "docs" / "reference")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert gen.returncode == 0, gen.stderr[-3000:]
    cli = (tmp_path / "docs" / "reference" / "cli.md").read_text()
    assert "## `emml train`" in cli and "--pack-seeds" in cli and "## `emml bench train`" in cli
    config = (tmp_path / "docs" / "reference" / "config.md").read_text()
    for section in ("## TrainConfig", "## DoomConfig", "## PPOConfig", "## ModelConfig"):
        assert section in config
    assert "| `max_steps` | `Positive` | `210` | Episode limit in agent steps" in config  # a field's own docstring
    build = _strict_build(tmp_path)
    assert build.returncode == 0, build.stderr[-3000:]
    assert (tmp_path / "site" / "reference" / "cli" / "index.html").is_file()
    assert (tmp_path / "site" / "experiments" / "index.html").is_file()


@pytest.mark.skipif(not MKDOCS, reason="mkdocs or mkdocs-material not installed (the dev extra: pip install -e .[dev])")
def test_a_broken_link_or_a_page_left_out_fails_the_strict_build(tmp_path):
    shutil.copy(ROOT / "mkdocs.yml", tmp_path / "mkdocs.yml")
    docs = tmp_path / "docs"
    shutil.copytree(ROOT / "docs", docs)
    for name in ("cli.md", "config.md"):  # the generated pages: stand-ins, so the nav finds them
        (docs / "reference" / name).parent.mkdir(exist_ok=True)
        (docs / "reference" / name).write_text(f"# {name}\n")
    (docs / "orphan.md").write_text("# Orphan\n\n[gone](fidelity.md#no-such-section)\n")
    build = _strict_build(tmp_path)
    assert build.returncode != 0
    assert "orphan.md" in build.stderr and "no-such-section" in build.stderr


def test_the_readme_fits_a_screen_or_two_and_leads_with_the_two_commands():
    text = README.read_text()
    assert len(text) < 8000
    block = text.split("```bash\n", 1)[1].split("```", 1)[0].splitlines()
    assert [line.split()[:2] for line in block] == [["make", "demo"], ["make", "test"]]
    assert "make test" in (ROOT / ".ci" / "run").read_text()  # CI runs the README's test command
    assert max(len(line) for line in text.splitlines() if line.startswith("|")) < 200  # no paragraph in a cell


def test_every_readme_link_exists_or_is_written_by_make_reports():
    from emml.report.claims_page import page_names

    written = {f"reports/{n}" for n in page_names("quick").values()} | {"reports/index.md"}
    links = re.findall(r"!?\[[^\]]*\]\(([^)\s#]+)[^)]*\)", README.read_text())
    assert any(link.startswith("reports/claims-quick") for link in links)  # the snapshot: make reports writes it
    assert any(link.startswith("docs/") for link in links)
    for link in links:
        if re.match(r"^[a-z]+:", link):
            continue
        assert (ROOT / link).exists() or link in written, link


def test_every_experiment_file_has_its_row_in_the_experiments_page():
    """docs/experiments.md lists each reproduce/experiments/NAME.toml as `NAME` in its table (a new experiment is not
    left undocumented; a retired one keeps its row only if it says so)."""
    page = (ROOT / "docs" / "experiments.md").read_text()
    listed = re.findall(r"^\| `(\w+)`( \([^)]*\))? \|", page, flags=re.M)
    files = set(list_experiments())
    assert files, "no experiment files found"
    assert files <= {name for name, _ in listed}, sorted(files - {name for name, _ in listed})
    for name, why in listed:
        assert name in files or "retired" in why, f"{name}: listed, but no reproduce/experiments/{name}.toml"
