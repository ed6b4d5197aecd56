"""The commits a run trained under (issue 60): each session's sha and frames in results.json, the table page's
footnote, and run dirs from before read as their single git_sha."""

import json

import pandas as pd

from emml.config.profiles import profile_config
from emml.runs.results import read_results
from emml.runs.rundir import RESULTS, last_started, record_result, results_payload, run_dir
from emml.runs.segments import (
    SEGMENTS,
    UNKNOWN,
    begin_segment,
    commits,
    read_run_segments,
    run_segments,
)


def test_each_session_is_a_segment_ending_where_the_next_began(tmp_path):
    begin_segment(tmp_path, "aaa", 0, now="t0")
    begin_segment(tmp_path, "bbb", 400_384, now="t1")
    assert run_segments(tmp_path, 1_500_160, "bbb") == [
        {"git_sha": "aaa", "frames": [0, 400_384], "started_at": "t0"},
        {"git_sha": "bbb", "frames": [400_384, 1_500_160], "started_at": "t1"},
    ]


def test_a_run_last_started_at_its_latest_session_else_its_results_else_never(tmp_path):
    noted, older, unknown = tmp_path / "noted", tmp_path / "older", tmp_path / "unknown"
    begin_segment(noted, "aaa", 0, now="2026-11-01T00:00:00+00:00")
    begin_segment(noted, "bbb", 400_384, now="2026-11-02T00:00:00+00:00")
    older.mkdir()
    (older / RESULTS).write_text(
        json.dumps({"run_id": "r", "table": "table2", "started_at": "2026-10-01T00:00:00+00:00"})
    )
    unknown.mkdir()
    assert last_started(noted) == "2026-11-02T00:00:00+00:00"
    assert last_started(older) == "2026-10-01T00:00:00+00:00"
    assert last_started(unknown) == "" < last_started(older) < last_started(noted)


def test_a_session_resumed_from_a_frame_replaces_the_sessions_noted_from_it_on(tmp_path):
    """A session killed before its first checkpoint trained nothing that was kept: the next, from the same frame,
    replaces it (and any noted after that frame)."""
    begin_segment(tmp_path, "aaa", 0)
    begin_segment(tmp_path, "bbb", 100)
    begin_segment(tmp_path, "ccc", 200)
    noted = begin_segment(tmp_path, "ddd", 100)
    assert [(s["git_sha"], s["from_frame"]) for s in noted] == [("aaa", 0), ("ddd", 100)]
    assert begin_segment(tmp_path / "new", "eee", 0)[0]["git_sha"] == "eee"  # a new run: one session from 0


def test_frames_trained_before_sessions_were_noted_are_unknowns(tmp_path):
    """A run begun under code from before, resumed under this: its first frames' commit is not known, and not
    guessed."""
    begin_segment(tmp_path, "bbb", 300)
    assert [(s["git_sha"], s["frames"]) for s in run_segments(tmp_path, 500, "bbb")] == [
        (UNKNOWN, [0, 300]),
        ("bbb", [300, 500]),
    ]
    (tmp_path / SEGMENTS).write_text('{"segments": [')  # torn: noted again from the next session
    assert run_segments(tmp_path, 500, "ccc") == [{"git_sha": "ccc", "frames": [0, 500], "started_at": None}]


def test_results_json_holds_the_segments_and_the_row_does_not(tmp_path):
    roots = {"run_root": str(tmp_path / "runs"), "results_root": str(tmp_path / "results"), "table": "t"}
    cfg = profile_config("quick", "easy", roots)
    begin_segment(run_dir(cfg), "aaa", 0)
    begin_segment(run_dir(cfg), "bbb", 1024)
    payload = results_payload(cfg, {"sgn_test": 0.5}, 2048, "bbb", "id")
    assert [(s["git_sha"], s["frames"]) for s in payload["segments"]] == [("aaa", [0, 1024]), ("bbb", [1024, 2048])]
    assert payload["git_sha"] == "bbb"  # the row's: the commit that finished it
    row = read_results(record_result(payload, cfg)).iloc[0]
    assert "segments" not in row and row["git_sha"] == "bbb"  # a pinned campaign's reader would read it as a metric


def test_a_row_an_older_writer_copied_the_segments_into_still_reads(tmp_path):
    path = tmp_path / "quick.csv"
    pd.DataFrame([{"run_name": "r", "git_sha": "12e0077", "segments": "[{'git_sha': 'a'}]", "sgn_test": 0.5}]).to_csv(
        path, index=False
    )
    df = read_results(path)
    assert df.loc[0, "segments"] == "[{'git_sha': 'a'}]" and df.loc[0, "sgn_test"] == 0.5


def test_a_run_dir_from_before_reads_as_its_single_sha():
    segments, recorded = read_run_segments({"git_sha": "9aa2a54", "frames": 5_000_448})
    assert not recorded and segments == [{"git_sha": "9aa2a54", "frames": [0, 5_000_448], "started_at": None}]
    assert read_run_segments({"git_sha": "x", "frames": float("nan")})[0][0]["frames"] == [0, 0]  # an empty cell


def test_consecutive_sessions_under_one_commit_are_one_commit():
    segments = [
        {"git_sha": "a", "frames": [0, 10]},
        {"git_sha": "a", "frames": [10, 20]},
        {"git_sha": "b", "frames": [20, 30]},
    ]
    assert commits(segments) == [("a", 0, 20), ("b", 20, 30)]


def test_a_run_resumed_under_another_commit_records_both_in_results_json(tmp_path, monkeypatch, no_leftovers):
    """End to end at the smoke profile: trained to 64 frames under one sha, extended to 192 under another."""
    import emml.rl.trainer as trainer

    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path}/mlflow.db")
    roots = {"run_root": str(tmp_path / "runs"), "results_root": str(tmp_path / "results"), "table": "test"}
    for sha, frames in (("aaa1111", 64), ("bbb2222", 192)):
        monkeypatch.setattr(trainer, "git_sha", lambda sha=sha: sha)
        cfg = profile_config("smoke", "easy", {**roots, "frames": frames, "eval_episodes": 1})
        result = trainer.train(cfg, quiet=True)
    saved = json.loads((result.run_dir / RESULTS).read_text())
    assert [(s["git_sha"], s["frames"]) for s in saved["segments"]] == [("aaa1111", [0, 64]), ("bbb2222", [64, 192])]
    assert saved["git_sha"] == "bbb2222" and saved["frames"] == 192
