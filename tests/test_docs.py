"""The docs site (issue 63): `make docs` builds the site strictly (no broken link or anchor, no page left out of the
nav, the generated CLI and config references included)."""

import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MKDOCS = importlib.util.find_spec("mkdocs") is not None and importlib.util.find_spec("material") is not None


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
    assert "| `max_steps` | `int` | `210` | Episode limit in agent steps" in config  # a field's own docstring
    build = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(tmp_path / "mkdocs.yml"), "-d", "site"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        env={"NO_MKDOCS_2_WARNING": "1", "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)},
    )
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
    build = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(tmp_path / "mkdocs.yml"), "-d", "site"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        env={"NO_MKDOCS_2_WARNING": "1", "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)},
    )
    assert build.returncode != 0
    assert "orphan.md" in build.stderr and "no-such-section" in build.stderr
