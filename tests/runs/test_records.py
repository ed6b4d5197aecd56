"""Files read back line by line (issue 54): a torn last line (a kill or a full disk mid-write) is cut back to the last
whole record with a one-line note; anything else that is not a record fails in one line naming the file and the
line. Covers the metrics mirror (emml/runs/records.py), the results CSV (emml/runs/results.py) and results.json
(emml/runs/rundir.py)."""

from __future__ import annotations

import pytest

from emml.runs.records import RecordError, cut_torn_tail, points_or_none, read_points
from emml.runs.results import read_results
from emml.runs.rundir import RunDirError, saved_config
from emml.runs.rundir import read_results as read_results_json

MIRROR = "step,key,value\n64,charts/fps,100.0\n64,losses/policy,-0.5\n128,charts/fps,nan\n"


def test_a_torn_mirror_tail_is_cut_back_with_a_note_and_read_without_it(tmp_path, capsys):
    path = tmp_path / "metrics.csv"
    path.write_text(MIRROR + "192,losses/pol")
    assert read_points(path)[-1][:2] == (128, "charts/fps")  # a reader leaves it out, and leaves the file alone
    assert path.read_text().endswith("192,losses/pol")
    said = cut_torn_tail(path)
    assert path.read_text() == MIRROR
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"note: {path}: line 5 was cut short (14 bytes")
    assert said in err and cut_torn_tail(path) is None  # whole now: nothing to say
    assert cut_torn_tail(tmp_path / "absent.csv") is None


@pytest.mark.parametrize(
    "text, line",
    [
        (MIRROR + "128,losses/po192,losses/policy,0.1\n" + "256,charts/fps,1.0\n", 5),  # a torn line appended onto
        (MIRROR.replace("64,losses/policy,-0.5", "garbage"), 3),
        ("step,key\n64,charts/fps,1.0\n", 1),
    ],
)
def test_a_mirror_line_that_is_no_point_is_named_by_file_and_line(tmp_path, text, line):
    path = tmp_path / "metrics.csv"
    path.write_text(text)
    with pytest.raises(RecordError, match=rf"^{path}: line {line}: ") as e:
        read_points(path)
    assert "\n" not in str(e.value)


def test_a_reader_of_many_runs_gets_none_for_a_damaged_mirror_named_once(tmp_path, capsys):
    """Issue 65: reports and --status read many runs; a damaged one costs that run only, and is named once however
    many readers read it (--status printed each note 2-3 times)."""
    path = tmp_path / "metrics.csv"
    path.write_text(MIRROR.replace("64,losses/policy,-0.5", "garbage"))
    assert points_or_none(path) is None and points_or_none(path, "not used") is None
    err = capsys.readouterr().err
    assert err.count(f"{path}: line 3: not a metric point") == 1 and err.count("\n") == 1
    assert points_or_none(tmp_path / "absent.csv") == [] and len(points_or_none(_whole(tmp_path))) == 3


def _whole(tmp_path):
    path = tmp_path / "whole.csv"
    path.write_text(MIRROR)
    return path


CSV = "run_name,seed,frames,sgn_test\na-s0,0,512,0.5\nb-s1,1,512,0.25\n"


def test_a_torn_results_csv_row_is_left_out_with_a_note(tmp_path, capsys):
    path = tmp_path / "smoke.csv"
    path.write_text(CSV + "c-s2,2,5")
    assert list(read_results(path)["run_name"]) == ["a-s0", "b-s1"]
    err = capsys.readouterr().err
    assert err.startswith(f"note: {path}: line 4 was cut short (3 of 4 fields") and err.count("\n") == 1
    path.write_text(CSV + "c-s2,2,512,0.75")  # every field, no newline: a whole row
    assert list(read_results(path)["run_name"]) == ["a-s0", "b-s1", "c-s2"] and capsys.readouterr().err == ""
    path.write_text(CSV.replace("b-s1,1,512", "b-s1,x,512"))  # not torn: named, never guessed
    with pytest.raises(ValueError, match=rf"^{path}: line 3: column 'seed' must hold an integer, found 'x'$"):
        read_results(path)


def test_a_damaged_results_json_is_named_by_file_and_line(tmp_path):
    path = tmp_path / "results.json"
    path.write_text('{\n  "run_id": "x",\n  "table": ')
    for read in (read_results_json, saved_config):
        with pytest.raises(RunDirError, match=rf"^{path}: not JSON \(.*line 3 column") as e:
            read(tmp_path)
        assert "\n" not in str(e.value)
    path.write_bytes(b"\xff\xfe")
    with pytest.raises(RunDirError, match="not UTF-8"):
        saved_config(tmp_path)
