"""The docs site and the README (issue 63): `make docs` builds the site strictly (no broken link or anchor, no page
left out of the nav, the generated CLI and config references included, the results of reports/ served under
results/ with the home linking the claims page and its figure), every link of docs/ resolves on GitHub, and the
README fits a screen or two, leads with the two commands CI runs, and links only what exists or what `make reports`
writes."""

import importlib.util
import posixpath
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


SKIP_NO_MKDOCS = pytest.mark.skipif(
    not MKDOCS, reason="mkdocs or mkdocs-material not installed (the dev extra: pip install -e .[dev])"
)
OWN = {"docs", "mkdocs.yml", "site", ".git", ".venv"}
"""What a site folder has of its own; the rest of the checkout is linked into it (the hooks, reports/, what links
leave the site for)."""


def _script(name):
    """scripts/NAME.py as a module (the hooks are loaded by path, as MkDocs loads them)."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _site_folder(folder, reference_stubs=False):
    """``folder`` laid out as the checkout for a build: its own mkdocs.yml and docs/ (no generated page), the rest
    of the checkout's top level linked in; the references as stand-ins when ``reference_stubs``."""
    shutil.copy(ROOT / "mkdocs.yml", folder / "mkdocs.yml")
    shutil.copytree(ROOT / "docs", folder / "docs", ignore=shutil.ignore_patterns("cli.md", "config.md"))
    for entry in ROOT.iterdir():
        if entry.name not in OWN and entry.name != "reports":
            (folder / entry.name).symlink_to(entry)
    (folder / "reports").mkdir()  # its own folder of links, so a test can add a page beside the real ones
    for entry in (ROOT / "reports").iterdir():
        (folder / "reports" / entry.name).symlink_to(entry)
    if reference_stubs:
        (folder / "docs" / "reference").mkdir(exist_ok=True)
        for name in ("cli.md", "config.md"):
            (folder / "docs" / "reference" / name).write_text(f"# {name}\n")
    return folder


def _strict_build(folder):
    """`mkdocs build --strict` of the site folder ``folder``, into folder/site."""
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(folder / "mkdocs.yml"), "-d", "site"],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=300,
        env={"NO_MKDOCS_2_WARNING": "1", "PATH": "/usr/bin:/bin", "HOME": str(folder)},
    )


LEAVING = (
    "# Links that leave the site\n\n[the claims file](../reproduce/claims.toml), [a table page](table2-quick.md)\n"
)
"""A report page whose links leave the site (to a committed file) and stay in it."""


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """The site as `make docs` builds it (the generated references, then `mkdocs build --strict`), in a temporary
    folder, with one report page more (`LEAVING`); (folder, the generator's run, the build's run)."""
    folder = _site_folder(tmp_path_factory.mktemp("site"))
    (folder / "reports" / "zz-leaving.md").write_text(LEAVING)
    gen = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "docs_reference.py"), str(folder / "docs" / "reference")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    build = _strict_build(folder) if gen.returncode == 0 else None
    return folder, gen, build


@SKIP_NO_MKDOCS
def test_the_docs_site_builds_strictly_with_its_generated_references(built):
    folder, gen, build = built
    assert gen.returncode == 0, gen.stderr[-3000:]
    cli = (folder / "docs" / "reference" / "cli.md").read_text()
    assert "## `emml train`" in cli and "--pack-seeds" in cli and "## `emml bench train`" in cli
    config = (folder / "docs" / "reference" / "config.md").read_text()
    for section in ("## TrainConfig", "## DoomConfig", "## PPOConfig", "## ModelConfig"):
        assert section in config
    assert "| `max_steps` | `Positive` | `210` | Episode limit in agent steps" in config  # a field's own docstring
    assert build.returncode == 0, build.stderr[-3000:]
    assert (folder / "site" / "reference" / "cli" / "index.html").is_file()
    assert (folder / "site" / "experiments" / "index.html").is_file()


def _hrefs(html, tag="a", attr="href"):
    return re.findall(rf"<{tag}\b[^>]*\b{attr}=\"([^\"]+)\"", html)


@SKIP_NO_MKDOCS
def test_the_home_links_the_claims_page_which_shows_its_figure(built):
    folder, _, build = built
    assert build.returncode == 0, build.stderr[-3000:]
    site = folder / "site"
    home = (site / "index.html").read_text()
    main = home[home.index('<article class="md-content__inner') :]  # the page itself, not the nav
    assert "results/claims-quick/" in _hrefs(main)
    assert "results/claims-quick.png" in _hrefs(main, "img", "src")  # the figure on the home too
    claims = site / "results" / "claims-quick" / "index.html"
    images = _hrefs(claims.read_text(), "img", "src")
    assert "../claims-quick.png" in images
    assert (claims.parent / "../claims-quick.png").resolve().read_bytes() == (
        ROOT / "reports" / "claims-quick.png"
    ).read_bytes()
    for name in (p.stem for p in (ROOT / "reports").glob("*.md")):  # every report page is served and in the nav
        url = "results/" if name == "index" else f"results/{name}/"
        assert (site / url / "index.html").is_file(), name
        assert url in _hrefs(home), name
    table = site / "results" / "table2-quick" / "index.html"
    for src in _hrefs(table.read_text(), "img", "src"):  # the table page's figures came along
        assert (table.parent / src).resolve().is_file(), src


@SKIP_NO_MKDOCS
def test_a_report_link_that_leaves_the_site_keeps_its_text_and_one_inside_stays_a_link(built):
    folder, _, build = built
    assert build.returncode == 0, build.stderr[-3000:]
    html = (folder / "site" / "results" / "zz-leaving" / "index.html").read_text()
    assert "the claims file" in html and "claims.toml" not in " ".join(_hrefs(html))  # no repo_url here: text only
    assert "../table2-quick/" in _hrefs(html)


@SKIP_NO_MKDOCS
def test_a_broken_link_or_a_page_left_out_fails_the_strict_build(tmp_path):
    docs = _site_folder(tmp_path, reference_stubs=True) / "docs"
    (docs / "orphan.md").write_text("# Orphan\n\n[gone](fidelity.md#no-such-section), [away](../no-such-folder/x.md)\n")
    build = _strict_build(tmp_path)
    assert build.returncode != 0
    assert "orphan.md" in build.stderr and "no-such-section" in build.stderr
    assert "no-such-folder" in build.stderr  # a link that leaves the site to nothing is not hidden


def _committed():
    """The files git tracks in the checkout and every folder above one: what GitHub shows."""
    out = subprocess.run(["git", "-C", str(ROOT), "ls-files"], capture_output=True, text=True, check=False)
    if out.returncode != 0 or not out.stdout:
        pytest.skip("not a git checkout: no committed files to resolve links against")
    files = set(out.stdout.splitlines())
    return files | {str(Path(f).parents[i]) for f in files for i in range(len(Path(f).parents) - 1)}


def test_every_relative_link_in_docs_resolves_to_a_committed_file():
    """docs/*.md read on GitHub: each relative link, resolved against its page, names a committed file or folder
    (a generated page such as reference/cli.md is not one)."""
    committed = _committed()
    checked = 0
    for page in sorted((ROOT / "docs").glob("*.md")):
        for target in re.findall(r"\]\(([^()\s]+)(?:\s+\"[^\"]*\")?\)", page.read_text()):
            path = target.split("#", 1)[0]
            if not path or re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target):
                continue
            resolved = posixpath.normpath(posixpath.join("docs", path))
            assert resolved in committed, f"{page.name}: {target} -> {resolved}, not committed"
            checked += 1
    assert checked > 50  # the pages do link each other


def test_the_docs_link_the_claims_page_and_its_figure_as_github_reads_them():
    text = (ROOT / "docs" / "index.md").read_text()
    assert "](../reports/claims-quick.md)" in text and "](../reports/claims-quick.png)" in text


def test_links_resolve_to_their_place_in_the_site_or_leave_it(tmp_path):
    pytest.importorskip("mkdocs")
    results = _script("docs_results")
    (tmp_path / "runs" / "r").mkdir(parents=True)
    (tmp_path / "runs" / "r" / "m.csv").write_text("x\n")
    served = {
        "docs/index.md": "index.md",
        "docs/reference/cli.md": "reference/cli.md",
        "reports/claims-quick.md": "results/claims-quick.md",
        "reports/claims-quick.png": "results/claims-quick.png",
    }
    url = "https://github.com/o/r"

    def link(target, page, repo_url=url):
        return results.site_link(target, page, served, tmp_path, repo_url)

    assert link("../reports/claims-quick.md#a", "docs/index.md") == "results/claims-quick.md#a"
    assert link("../../reports/claims-quick.png", "docs/reference/cli.md") == "../results/claims-quick.png"
    assert link("claims-quick.png", "reports/claims-quick.md") == "claims-quick.png"
    assert link("../docs/index.md", "reports/claims-quick.md") == "../index.md"
    assert link("../runs/r/m.csv", "reports/claims-quick.md") == f"{url}/blob/HEAD/runs/r/m.csv"
    assert link("../runs/r/", "reports/claims-quick.md") == f"{url}/tree/HEAD/runs/r"
    assert link("../runs/r/m.csv", "reports/claims-quick.md", None) == ""  # no repository: text only
    for kept in ("../runs/r/gone.csv", "https://x.org/a.md", "#anchor", "/abs.md", "../../../outside.md"):
        assert link(kept, "reports/claims-quick.md") is None, kept

    text = (
        'A [run](../runs/r/m.csv), ![fig](claims-quick.png "t"), [ok](https://x.org), '
        "`[code](../runs/r/m.csv)`\n```\n[fenced](../runs/r/m.csv)\n```\n[`multi`\nline](../runs/r/m.csv)"
    )
    out = results.rewrite_links(text, "reports/claims-quick.md", served, tmp_path, None)
    assert out == (
        'A run, ![fig](claims-quick.png "t"), [ok](https://x.org), '
        "`[code](../runs/r/m.csv)`\n```\n[fenced](../runs/r/m.csv)\n```\n`multi`\nline"
    )


def test_the_results_section_lists_every_report_page_a_detail_after_its_page():
    pytest.importorskip("mkdocs")
    results = _script("docs_results")
    pages = results.nav_order(["table2-quick.md", "claims-paper-detail.md", "index.md", "claims-paper.md"])
    assert pages == ["index.md", "claims-paper.md", "claims-paper-detail.md", "table2-quick.md"]
    nav = [{"Home": "index.md"}, {"Results": [{"Overview": "results/index.md"}, "results/claims-quick.md"]}]
    found = [f"results/{n}" for n in ("index.md", "claims-paper.md", "claims-quick-detail.md", "table2-quick.md")]
    assert results.with_results(nav, found)[1]["Results"] == [
        {"Overview": "results/index.md"},
        "results/claims-quick.md",
        "results/claims-quick-detail.md",
        "results/claims-paper.md",
        "results/table2-quick.md",
    ]
    with pytest.raises(Exception, match="no 'Results' section"):
        results.with_results([{"Home": "index.md"}], found)


def test_the_repository_link_comes_from_the_git_remote_else_pyproject_without_credentials(tmp_path):
    repo = _script("docs_repo")
    assert repo.web_url("git@github.com:o/r.git") == "https://github.com/o/r"
    assert repo.web_url("ssh://git@gitlab.example.org:2222/g/o/r.git") == "https://gitlab.example.org/g/o/r"
    assert repo.web_url("https://user:token@github.com/o/r.git") == "https://github.com/o/r"
    for local in ("/srv/git/r.git", "file:///srv/git/r.git", "../r", "C:/r"):
        assert repo.web_url(local) is None, local
    assert repo.repository_url(tmp_path) is None  # neither a remote nor pyproject.toml
    (tmp_path / "pyproject.toml").write_text('[project]\nname = "x"\n[project.urls]\nSource = "https://h.org/o/x/"\n')
    assert repo.repository_url(tmp_path) == "https://h.org/o/x"
    git = ["git", "-C", str(tmp_path)]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "remote", "add", "backup", "/srv/git/x.git"], check=True)
    subprocess.run([*git, "remote", "add", "mirror", "git@gitlab.com:m/x.git"], check=True)
    subprocess.run([*git, "remote", "add", "origin", "git@github.com:o/x.git"], check=True)
    assert repo.repository_url(tmp_path) == "https://github.com/o/x"  # origin first, though git lists it last
    subprocess.run([*git, "remote", "remove", "origin"], check=True)
    assert repo.repository_url(tmp_path) == "https://gitlab.com/m/x"  # then the first with a web address


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
