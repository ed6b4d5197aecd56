"""The results CSV keeps every column's type: shas that look like numbers survive a round trip."""

import string
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from emml.runs.results import (
    QUESTION_COLUMNS,
    QUESTIONS_SUFFIX,
    ResultsError,
    questions_path,
    read_questions,
    read_results,
    upsert_questions,
    upsert_result,
)


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
        if path.stem.endswith(QUESTIONS_SUFFIX):  # the per-question file beside a table: its runs are the table's
            table = read_results(path.with_name(path.name.replace(QUESTIONS_SUFFIX, "")))
            assert set(read_questions(path)["run_id"]) <= set(table["run_id"]), path
            continue
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


# --- EQA per question (issue 81) -----------------------------------------------------------------------------------
def _counts(*pairs) -> dict:
    return {q: {"successes": k, "episodes": n} for q, k, n in pairs}


def test_per_question_rows_of_one_run_replace_its_own_and_keep_every_other_run_s(tmp_path):
    path = questions_path(tmp_path / "table2" / "quick.csv")
    assert path == tmp_path / "table2" / "quick-questions.csv"
    upsert_questions(path, "b-run", "id-b", {"eqa_test": _counts(("q2", 1, 3), ("q1", 0, 2))})
    upsert_questions(path, "a-run", "id-a", {"eqa_train": _counts(("q1", 2, 2)), "eqa_test": _counts(("q1", 1, 5))})
    upsert_questions(path, "b-run", "id-b2", {"eqa_test": _counts(("q1", 4, 5))})  # b trained again: its rows only
    rows = read_questions(path)
    assert list(rows.columns) == list(QUESTION_COLUMNS)
    got = rows[["run_name", "run_id", "split", "question", "successes", "episodes"]].values.tolist()
    assert got == [
        ["a-run", "id-a", "test", "q1", 1, 5],
        ["a-run", "id-a", "train", "q1", 2, 2],
        ["b-run", "id-b2", "test", "q1", 4, 5],
    ]
    assert set(rows["task"]) == {"eqa"} and rows["successes"].dtype.kind == "i"
    assert read_questions(tmp_path / "absent.csv").columns.tolist() == list(QUESTION_COLUMNS)


def test_a_bad_per_question_file_or_setting_is_named(tmp_path):
    path = tmp_path / "quick-questions.csv"
    path.write_text("run_name,run_id,task,split,question,successes,episodes\nr,i,eqa,test,q,3,2\n")
    with pytest.raises(ResultsError, match="line 2: successes must lie between 0 and episodes, found 3 of 2"):
        read_questions(path)
    path.write_text("run_name,run_id,task,split,question,successes\nr,i,eqa,test,q,3\n")
    with pytest.raises(ResultsError, match="no column 'episodes'"):
        read_questions(path)
    with pytest.raises(ValueError, match="setting 'eqa' is not '<task>_<split>'"):
        upsert_questions(tmp_path / "x.csv", "r", "i", {"eqa": _counts(("q", 1, 1))})
    assert not (tmp_path / "x.csv").exists()


def test_a_full_disk_leaves_the_per_question_file_as_it_was(tmp_path, monkeypatch):
    import errno

    import pandas as pd

    from emml.runs.diskspace import NoSpaceError

    path = tmp_path / "quick-questions.csv"
    upsert_questions(path, "a-run", "id-a", {"eqa_test": _counts(("q1", 1, 5))})
    before = path.read_bytes()

    def fills_the_disk(self, target, **kwargs):
        Path(target).write_text("run_name,ru")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(pd.DataFrame, "to_csv", fills_the_disk)
    with pytest.raises(NoSpaceError, match="quick-questions.csv, left as it was"):
        upsert_questions(path, "b-run", "id-b", {"eqa_test": _counts(("q1", 1, 5))})
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["quick-questions.csv", "quick-questions.csv.lock"]
