"""MkDocs hook (mkdocs.yml `hooks:`): the results of reports/ in the docs site, and links that read the same on
GitHub and in the site.

- Every file of reports/ (what `make reports` writes: the claims pages, the table pages, their figures, .tex and
  .pdf) is served in the site under results/ at build time, from where it lies: nothing is copied into docs/.
- The nav's `Results` section (mkdocs.yml) lists its own entries first, then every other page of reports/, a claims
  page's detail right after it. A missing `Results` section is an error.
- Links are written as GitHub reads them, relative to the file's place in the repository (docs/index.md links
  `../reports/claims-quick.md`, a report `table2-quick.md`). Before each page is rendered, a link that resolves to
  a file the site serves is rewritten to that file's place in the site. A link that leaves the site (e.g. a report's
  `../runs/...`, a page's `../emml/config/`) to something that exists in the checkout becomes a link to it in the
  repository (`repo_url` + `/blob/HEAD/PATH`, `/tree/HEAD/PATH` for a folder) or, with no `repo_url`, its text
  alone. A link to nothing is left as written, so the strict build fails on it. Links in code are not touched."""

from __future__ import annotations

import os
import posixpath
import re
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File

REPORTS = "reports"
"""The folder of the checkout (beside mkdocs.yml) whose files the site serves."""
SITE_DIR = "results"
"""Where the site serves them (`results/claims-quick.md` is reports/claims-quick.md)."""
SECTION = "Results"
"""The nav section that lists the report pages."""

LINK = re.compile(
    r"(?P<code>```.*?```|`[^`\n]*`)"
    r"|(?P<label>!?\[(?:[^\[\]]|\[[^\[\]]*\])*\])\((?P<target>[^()\s]+)(?P<title>\s+\"[^\"]*\")?\)",
    flags=re.S,
)
"""A fenced block or code span (kept as is), or an inline link or image with an optional title."""


def report_files(root: Path) -> list[str]:
    """The files of reports/ under ``root``, as paths relative to it, sorted; hidden ones left out."""
    folder = root / REPORTS
    if not folder.is_dir():
        return []
    return sorted(
        p.relative_to(folder).as_posix()
        for p in folder.rglob("*")
        if p.is_file() and not any(part.startswith(".") for part in p.relative_to(folder).parts)
    )


def nav_order(names: list[str]) -> list[str]:
    """Report pages in nav order: the overview (index.md), the claims pages (each followed by its detail), the
    rest by name."""

    def key(name: str) -> tuple:
        stem = name.removesuffix(".md")
        return (stem != "index", not stem.startswith("claims-"), stem.removesuffix("-detail"), stem.endswith("-detail"))

    return sorted(names, key=key)


def with_results(nav: list, pages: list[str]) -> list:
    """``nav`` with its `Results` section extended by every page of ``pages`` (site paths, in `nav_order`) it does
    not list yet: a detail page right after its page, the others after the section's own entries."""
    for item in nav:
        if isinstance(item, dict) and SECTION in item:
            entries = item[SECTION] if isinstance(item[SECTION], list) else [item[SECTION]]
            paths = [v if isinstance(v, str) else next(iter(v.values())) for v in entries]
            for page in pages:
                if page in paths:
                    continue
                main = page.replace("-detail.md", ".md") if page.endswith("-detail.md") else None
                at = paths.index(main) + 1 if main in paths else len(paths)
                entries.insert(at, page)
                paths.insert(at, page)
            item[SECTION] = entries
            return nav
    raise PluginError(f"mkdocs.yml: the nav has no '{SECTION}' section to list the pages of {REPORTS}/ in")


def site_link(target: str, page: str, served: dict[str, str], root: Path, repo_url: str | None) -> str | None:
    """What a link ``target`` written in the repository file ``page`` (a path relative to ``root``) becomes in the
    site: a path relative to the page's place in the site when it resolves to a file the site serves (``served``
    maps repository paths to site paths), a repository address or "" (text only) when it resolves to something else
    in the checkout, None (left as written) for an address, an anchor or a path to nothing."""
    if re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target) or target.startswith(("#", "/")):
        return None
    path, hash_, anchor = target.partition("#")
    resolved = posixpath.normpath(posixpath.join(posixpath.dirname(page), path))
    fragment = hash_ + anchor
    if resolved in served:
        here = posixpath.dirname(served[page])
        return posixpath.relpath(served[resolved], here or ".") + fragment
    if resolved.startswith("..") or not (root / resolved).exists():
        return None
    if not repo_url:
        return ""
    kind = "tree" if (root / resolved).is_dir() else "blob"
    return f"{repo_url.rstrip('/')}/{kind}/HEAD/{resolved}{fragment}"


def rewrite_links(markdown: str, page: str, served: dict[str, str], root: Path, repo_url: str | None) -> str:
    """``markdown`` of the repository file ``page`` with each link replaced as `site_link` says."""

    def replace(match: re.Match) -> str:
        if match.group("code"):
            return match.group(0)
        new = site_link(match.group("target"), page, served, root, repo_url)
        if new is None:
            return match.group(0)
        label = match.group("label")
        if new == "":
            return label.lstrip("!")[1:-1]
        return f"{label}({new}{match.group('title') or ''})"

    return LINK.sub(replace, markdown)


def _root(config) -> Path:
    return Path(config.config_file_path).resolve().parent


def _served(config, files) -> dict[str, str]:
    """Repository path -> site path of every file the site serves (docs/ and reports/)."""
    root = _root(config)
    docs = Path(config.docs_dir).resolve().relative_to(root).as_posix()
    served = {}
    for file in files:  # results/ holds only reports: on_files refuses a docs/results/
        if file.src_uri.startswith(f"{SITE_DIR}/"):
            served[f"{REPORTS}/{file.src_uri.removeprefix(SITE_DIR + '/')}"] = file.src_uri
        else:
            served[f"{docs}/{file.src_uri}"] = file.src_uri
    return served


def on_config(config):
    """Extends the nav's Results section with the pages of reports/ (and has `mkdocs serve` watch that folder)."""
    root = _root(config)
    pages = [f"{SITE_DIR}/{n}" for n in nav_order([n for n in report_files(root) if n.endswith(".md")])]
    config.nav = with_results(config.nav or [], pages)
    if (root / REPORTS).is_dir():
        config.watch.append(str(root / REPORTS))
    return config


def on_files(files, config):
    """Serves every file of reports/ under results/ (an error if docs/ has a results/ of its own)."""
    root = _root(config)
    for name in report_files(root):
        uri = f"{SITE_DIR}/{name}"
        if files.get_file_from_path(uri) is not None:
            raise PluginError(f"{config.docs_dir}/{uri}: {SITE_DIR}/ is where the site serves {REPORTS}/")
        files.append(File.generated(config, uri, abs_src_path=os.fspath(root / REPORTS / name)))
    return files


def on_page_markdown(markdown, page, config, files):
    """Rewrites the page's links from repository paths to site paths (see the module's docstring)."""
    served = _served(config, files)
    repo_path = next(path for path, uri in served.items() if uri == page.file.src_uri)
    return rewrite_links(markdown, repo_path, served, _root(config), config.repo_url)
