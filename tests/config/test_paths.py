"""The checkout's folders from a campaign's pinned worktree (issue 54): a pinned campaign runs the code of
<checkout>/.campaign/<sha>/ but its relative roots, and the guard that keeps smoke numbers out of the committed
results/, resolve under the checkout it was made from."""

from __future__ import annotations

import pytest

import emml.config.paths
from emml.config.paths import PIN_DIR, checkout_root, project_path, project_root
from emml.config.profiles import refuse_committed


@pytest.fixture
def pinned(tmp_path, monkeypatch):
    checkout = tmp_path / "checkout"
    tree = checkout / PIN_DIR / "0123456789ab"
    tree.mkdir(parents=True)
    (checkout / "pyproject.toml").write_text("")
    (tree / "pyproject.toml").write_text("")
    monkeypatch.setattr(emml.config.paths, "project_root", lambda: tree)
    return checkout


def test_a_pinned_worktree_resolves_the_checkouts_folders(pinned):
    assert project_root() != pinned and checkout_root() == pinned
    assert project_path("scratch/runs") == pinned / "scratch" / "runs"  # a smoke step's default run root
    assert project_path("/abs/runs").as_posix() == "/abs/runs"


def test_the_smoke_guard_checks_the_checkouts_results_from_a_pinned_worktree(pinned):
    with pytest.raises(ValueError, match=rf"results CSV {pinned}/results/table2/smoke.csv: the 'smoke' profile's"):
        refuse_committed("smoke", "results/table2/smoke.csv", "results CSV")
    with pytest.raises(ValueError, match="not results"):
        refuse_committed("smoke", pinned / "results" / "table2" / "smoke.csv", "results CSV")
    refuse_committed("smoke", "scratch/results/table2/smoke.csv", "results CSV")  # its default: allowed


def test_a_checkout_is_its_own_root():
    assert checkout_root() == project_root()
