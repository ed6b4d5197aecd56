"""Files written whole or not at all (emml/runs/atomic.py, issue 65): a write stopped mid-way (an error, Ctrl-C, a kill
-9, a full disk) leaves the old file or none under the final name, never a partial one; and every file `emml
reports` writes goes through it."""

from __future__ import annotations

import errno
import os
import re
import time
from pathlib import Path

import pytest

from emml.runs.atomic import STALE_TMP_S, replacing, write_text
from emml.runs.diskspace import NoSpaceError


def test_until_the_block_ends_the_final_name_holds_the_old_file(tmp_path):
    """What a kill -9 at any point of the write would leave: the old file under its name (the new bytes only in a
    hidden temp file beside it, which no reader globs)."""
    path = tmp_path / "page.md"
    path.write_text("old")
    with replacing(path) as tmp:
        tmp.write_text("new, half")
        assert path.read_text() == "old" and tmp.parent == path.parent and tmp.name.startswith(".page.md.")
        assert list(tmp_path.glob("*.md")) == [path] and tmp.suffix == ".tmp"  # no "*.md" reader sees it
    assert path.read_text() == "new, half" and [p.name for p in tmp_path.iterdir()] == ["page.md"]
    plain = tmp_path / "plain.md"
    plain.write_text("x")  # the mode every reader had before: mkstemp's 0600 would lock other users out
    assert path.stat().st_mode & 0o777 == plain.stat().st_mode & 0o777


@pytest.mark.parametrize("stop", [KeyboardInterrupt, RuntimeError, SystemExit])
def test_a_write_stopped_mid_way_leaves_the_old_file_or_none(tmp_path, stop):
    old, none = tmp_path / "old.png", tmp_path / "none.png"
    old.write_bytes(b"old figure")
    for path in (old, none):
        with pytest.raises(stop), replacing(path) as tmp:
            tmp.write_bytes(b"half a fig")
            raise stop()
    assert old.read_bytes() == b"old figure" and not none.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.png"]  # no temp file left by an orderly stop


def test_a_full_disk_is_one_line_naming_the_folder_and_the_old_file_is_kept(tmp_path):
    path = tmp_path / "reports" / "index.md"
    write_text(path, "old index")
    with pytest.raises(NoSpaceError) as e, replacing(path, then="free some space and rerun the same command") as tmp:
        tmp.write_text("half")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert str(e.value) == (
        f"no space left on {path.parent} (writing index.md, left as it was): free some space and rerun the same command"
    )
    assert path.read_text() == "old index" and len(list(path.parent.iterdir())) == 1


def test_a_figure_stopped_mid_save_leaves_the_old_figure(tmp_path):
    """Issue 65: a kill of `emml reports` left table2-quick-curves.png at 0 bytes under its final name."""
    import matplotlib.pyplot as plt

    from emml.report.savefig import save

    path = tmp_path / "curves.png"
    fig = plt.figure()
    save(fig, path)
    before = path.read_bytes()

    def half(target, **kwargs):  # a savefig that dies after writing part of the file
        Path(target).write_bytes(before[:10])
        raise KeyboardInterrupt

    fig.savefig = half
    with pytest.raises(KeyboardInterrupt):
        save(fig, path)
    assert path.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["curves.png"]
    fig.savefig = lambda target, **kwargs: (_ for _ in ()).throw(OSError(errno.ENOSPC, "No space left on device"))
    with pytest.raises(NoSpaceError, match=rf"^no space left on {tmp_path} \(writing curves.png, left as it was\)"):
        save(fig, path)
    assert path.read_bytes() == before
    plt.close(fig)


def test_every_file_a_report_writes_goes_through_the_atomic_writer():
    """emml/report/ writes pages, tables and figures only through emml/runs/atomic.py (savefig.save included): no
    `write_text`, `open(..., 'w')`, PIL `.save(path` or `savefig(path` of its own."""
    root = Path(__file__).resolve().parents[2] / "emml" / "report"
    direct = re.compile(
        r"\.write_text\(|\.write_bytes\(|open\([^)]*['\"][wa]b?['\"]|\.save\((?!tmp\b)|\.savefig\((?!tmp\b)"
    )
    found = [
        f"{p.name}:{n}: {line.strip()}"
        for p in sorted(root.glob("*.py"))
        for n, line in enumerate(p.read_text().splitlines(), 1)
        if direct.search(line) and not line.lstrip().startswith(("#", '"""', "``"))
    ]
    assert not found, found


def test_the_next_write_removes_the_temp_files_a_kill_left_an_hour_ago_not_a_write_under_way(tmp_path):
    """A kill -9 mid-write leaves a hidden `.<name>.*.tmp`; the next write of that file removes it once it is older
    than STALE_TMP_S, and leaves a fresh one (another writer's, under way) and another file's alone."""
    path = tmp_path / "results.csv"
    stale, fresh = tmp_path / ".results.csv.a1.tmp", tmp_path / ".results.csv.b2.tmp"
    other = tmp_path / ".metrics.csv.c3.tmp"
    for tmp in (stale, fresh, other):
        tmp.write_text("half a fi")
    old = time.time() - STALE_TMP_S - 10
    for tmp in (stale, other):
        os.utime(tmp, (old, old))
    write_text(path, "whole\n")
    assert path.read_text() == "whole\n"
    assert not stale.exists() and fresh.exists() and other.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [".metrics.csv.c3.tmp", ".results.csv.b2.tmp", "results.csv"]
