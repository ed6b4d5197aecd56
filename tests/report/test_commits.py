"""The table page's footnote on the commits its runs trained under (emml/report/commits.py)."""

import json

import pandas as pd

from emml.config.schema import TrainConfig
from emml.experiments.plan import PlannedRun
from emml.report.commits import commits_note
from emml.runs.rundir import RESULTS


def test_the_table_page_lists_the_runs_trained_under_several_commits(tmp_path):
    runs = tmp_path / "runs"
    several = {"git_sha": "bbb", "frames": 5_000_448, "segments": [
        {"git_sha": "aaa", "frames": [0, 400_384]}, {"git_sha": "bbb", "frames": [400_384, 5_000_448]}]}  # fmt: skip
    one = {"git_sha": "ccc", "frames": 1_500_160, "segments": [{"git_sha": "ccc", "frames": [0, 1_500_160]}]}
    for name, payload in (("hard", several), ("easy", one)):
        (runs / "table2" / name).mkdir(parents=True)
        (runs / "table2" / name / RESULTS).write_text(json.dumps(payload))
    rows = pd.DataFrame(
        [
            {"run_name": n, "table": "table2", "git_sha": s, "frames": f}
            for n, s, f in (("hard", "bbb", 5_000_448), ("easy", "ccc", 1_500_160), ("old", "ddd", 1_500_160))
        ]
    )
    cfg = TrainConfig(table="table2", run_root=str(runs))
    hard, easy, old = (PlannedRun(None, cfg, name, "finished") for name in ("hard", "easy", "old"))
    (note,) = [line for line in commits_note(rows, [hard, easy]) if line]
    assert "`hard`: aaa frames 0–400,384, bbb frames 400,384–5,000,448" in note and "`easy`" not in note
    assert "record only" not in note
    (note,) = [line for line in commits_note(rows, [easy, old]) if line]  # 'old': no run dir here
    assert "1 of 2 runs record only the commit that finished them" in note and "several" not in note
    assert commits_note(rows, []) == []
