"""scripts/device-tree (issue 51): a device call sends the checkout's tracked files, at most 64 MiB; `slim` keeps
the committed run dirs and reports from travelling (untracked in the index only, ignored) and `restore` puts the
checkout back exactly as committed, on a throwaway git repository."""

import shutil
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "device-tree"


def git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=repo, check=True, capture_output=True, text=True).stdout


@pytest.fixture
def repo(tmp_path):
    repo = tmp_path / "checkout"
    for path in ("emml/a.py", "runs/t/r/checkpoint.pt", "reports/x.md"):
        (repo / path).parent.mkdir(parents=True, exist_ok=True)
        (repo / path).write_text(path)
    (repo / "scripts").mkdir()
    shutil.copy(SCRIPT, repo / "scripts" / "device-tree")
    git(repo, "init", "-q")
    git(repo, "add", "-A")
    git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "x")
    return repo


def test_slim_leaves_only_the_code_to_travel_and_restore_gives_the_commit_back(repo):
    subprocess.run([repo / "scripts" / "device-tree", "slim"], check=True, capture_output=True)
    travels = git(repo, "ls-files").split() + git(repo, "ls-files", "--others", "--exclude-standard").split()
    assert sorted(travels) == ["emml/a.py", "scripts/device-tree"]
    assert (repo / "runs/t/r/checkpoint.pt").read_text() == "runs/t/r/checkpoint.pt"  # the files stay on disk
    subprocess.run([repo / "scripts" / "device-tree", "restore"], check=True, capture_output=True)
    assert git(repo, "status", "--porcelain") == ""
    assert "/runs/" not in (repo / ".git/info/exclude").read_text()


def test_slim_refuses_while_something_is_staged(repo):
    (repo / "emml/a.py").write_text("changed")
    git(repo, "add", "emml/a.py")
    done = subprocess.run([repo / "scripts" / "device-tree", "slim"], capture_output=True, text=True)
    assert done.returncode == 1 and "staged changes" in done.stderr
    assert "runs/t/r/checkpoint.pt" in git(repo, "ls-files")
