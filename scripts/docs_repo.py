"""MkDocs hook (mkdocs.yml `hooks:`): the site's link back to the repository, found at build time.

`repo_url` is taken, in this order, from mkdocs.yml itself, the git remote `origin` (else the first remote) of the
checkout that holds mkdocs.yml, or the `Repository`/`Source`/`Homepage` entry of `[project.urls]` in its
pyproject.toml. A remote is turned into its web address (`git@host:owner/name.git` -> `https://host/owner/name`) and
any user or token in it is dropped, so no credential reaches the site; a remote that is a local path has no web
address and is skipped. When none is found the site has no repository link. `edit_uri` is never set here: the site
has no "edit this page" link, which would need the default branch's name."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path
from urllib.parse import urlsplit

import tomllib

URL_KEYS = ("repository", "source", "source code", "homepage")
"""The `[project.urls]` entries read, in this order (case-insensitive), when the checkout has no git remote."""


def web_url(remote: str) -> str | None:
    """The https address of a git remote (scp-like `git@host:path`, ssh://, git:// or http(s)://), without user,
    token or trailing `.git`; None for a local path (`C:/r` included) or a host that is no domain name (an ssh
    alias)."""
    remote = remote.strip()
    scp = re.fullmatch(r"(?:[^@/\s]+@)?([^:/\s]+):(?!//)(.+)", remote)
    if scp and "://" not in remote:
        host, path = scp.group(1), scp.group(2)
    else:
        parts = urlsplit(remote)
        if parts.scheme not in ("http", "https", "ssh", "git", "git+ssh") or not parts.hostname:
            return None
        host, path = parts.hostname, parts.path
    path = path.strip("/").removesuffix(".git")
    return f"https://{host}/{path}" if path and "." in host else None


def git_remote_url(root: Path) -> str | None:
    """The web address of `origin`, else of the first remote, of the git checkout at ``root``; None without one."""
    try:
        out = subprocess.run(
            ["git", "-C", str(root), "remote", "-v"], capture_output=True, text=True, timeout=30, check=False
        ).stdout
    except (OSError, subprocess.TimeoutExpired):
        return None
    remotes = [line.split()[:2] for line in out.splitlines() if len(line.split()) >= 2]
    remotes.sort(key=lambda r: r[0] != "origin")  # origin first, the rest in git's order
    for _, address in remotes:
        url = web_url(address)
        if url:
            return url
    return None


def project_url(root: Path) -> str | None:
    """The repository address that pyproject.toml at ``root`` names in `[project.urls]`; None without one."""
    path = root / "pyproject.toml"
    if not path.is_file():
        return None
    urls = {k.lower(): v for k, v in tomllib.loads(path.read_text()).get("project", {}).get("urls", {}).items()}
    return next((urls[k].rstrip("/") for k in URL_KEYS if k in urls), None)


def repository_url(root: Path) -> str | None:
    """The repository's web address: the git remote first, then pyproject.toml; None when neither names one."""
    return git_remote_url(root) or project_url(root)


def on_config(config):
    """Sets `repo_url` (and `repo_name`, which the theme shows beside it) unless mkdocs.yml sets it."""
    if config.repo_url:
        return config
    url = repository_url(Path(config.config_file_path).resolve().parent)
    if url:
        config.repo_url = url
        config.repo_name = "GitHub" if urlsplit(url).hostname == "github.com" else urlsplit(url).path.strip("/")
    return config
