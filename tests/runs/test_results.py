"""The results CSV keeps every column's type: shas that look like numbers survive a round trip."""

import string
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from emml.runs.results import read_results, upsert_result


def _row(name: str, sha: str, **extra) -> dict:
    row = dict(
        run_name=name,
        table="t",
        model="dual_attention",
        difficulty="easy",
        aux=True,
        seed=0,
        profile="smoke",
        frames=512,
        git_sha=sha,
        run_id="1234",
        eval_episodes=3,
        tasks="both",
        shaping=True,
        sgn_train=0.5,
        sgn_test=0.25,
    )
    row.update(extra)
    return row


@pytest.mark.parametrize("sha", ["12e0077", "1234567", "0000001", "1e5", "nan", "deadbee", "0x1f"])
def test_a_sha_that_looks_like_a_number_round_trips(tmp_path, sha):
    path = tmp_path / "smoke.csv"
    upsert_result(path, _row("a", sha))
    upsert_result(path, _row("b", "abc1234"))  # a second write reads the first back: it must not convert it
    df = read_results(path)
    assert list(df["git_sha"]) == [sha, "abc1234"]
    assert list(df["run_id"]) == ["1234", "1234"]
    assert df["seed"].tolist() == [0, 0] and df["aux"].tolist() == [True, True]
    assert df["sgn_train"].tolist() == [0.5, 0.5]


@settings(max_examples=50, deadline=None)
@given(st.text(alphabet=string.hexdigits.lower() + "e+-.", min_size=1, max_size=12))
def test_any_sha_round_trips(tmp_path_factory, sha):
    path = tmp_path_factory.mktemp("r") / "smoke.csv"
    upsert_result(path, _row("a", sha))
    upsert_result(path, _row("a", sha, sgn_train=1.0))  # the upsert replaces, never duplicates
    df = read_results(path)
    assert df["git_sha"].tolist() == [sha] and df["sgn_train"].tolist() == [1.0]


def test_a_missing_metric_reads_as_nan_and_a_bad_cell_is_named(tmp_path):
    path = tmp_path / "smoke.csv"
    upsert_result(path, _row("a", "12e0077"))
    upsert_result(path, _row("b", "12e0077", eqa_train=0.75))
    df = read_results(path).set_index("run_name")
    assert df.loc["b", "eqa_train"] == 0.75 and df["eqa_train"].isna()["a"]
    path.write_text(path.read_text().replace(",512,", ",lots,", 1))
    with pytest.raises(ValueError, match=r": line 2: column 'frames' must hold an integer, found 'lots'$"):
        read_results(path)


def test_a_full_disk_leaves_the_results_csv_as_it_was(tmp_path, monkeypatch):
    import errno

    import pandas as pd

    from emml.runs.diskspace import NoSpaceError

    path = tmp_path / "smoke.csv"
    upsert_result(path, _row("a", "abc1234"))
    before = path.read_bytes()

    def fills_the_disk(self, target, **kwargs):
        Path(target).write_text("run_name,ta")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(pd.DataFrame, "to_csv", fills_the_disk)
    with pytest.raises(NoSpaceError, match=rf"^no space left on {tmp_path} \(writing smoke.csv, left as it was\)"):
        upsert_result(path, _row("b", "abc1234"))
    assert path.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["smoke.csv", "smoke.csv.lock"]


def test_the_committed_results_read_back_with_real_shas():
    from emml.config.paths import project_root

    for path in sorted((project_root() / "results").glob("*/*.csv")):
        shas = read_results(path)["git_sha"]
        assert shas.str.fullmatch(r"[0-9a-f]{7,40}").all(), (path, shas.unique())


def test_eval_seed_reads_back_from_rows_before_it_and_from_code_before_it(tmp_path):
    """eval_seed (issue 33) is empty in older rows, and code from before it rewrites it as a float ('10000.0')."""
    path = tmp_path / "quick.csv"
    upsert_result(path, _row("old", "abc1234"))
    upsert_result(path, _row("new", "abc1234", eval_seed=10_000, scored_sha="12e0077"))
    df = read_results(path).set_index("run_name")
    assert df.loc["new", "eval_seed"] == 10_000 and df["eval_seed"].isna()["old"]
    assert df.loc["new", "scored_sha"] == "12e0077" and df.loc["old", "scored_sha"] == ""
    path.write_text(path.read_text().replace(",10000,", ",10000.0,"))  # as an older writer leaves it
    assert read_results(path).set_index("run_name").loc["new", "eval_seed"] == 10_000
    path.write_text(path.read_text().replace(",10000.0,", ",10000.5,"))
    with pytest.raises(ValueError, match="'eval_seed' must hold an integer"):
        read_results(path)
