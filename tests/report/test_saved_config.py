"""A run's config in its results.json, and its backfill from the checkpoint, on FIXTURE run dirs in tmp_path (a
checkpoint holding only what the backfill reads)."""

import json

import pandas as pd
import torch

from emml.config.profiles import profile_config
from emml.report.saved_config import backfill_config, run_dirs
from emml.runs.naming import run_name
from emml.runs.rundir import saved_config


def fixture_run(root, finished=True, results=True, **fields):
    """FIXTURE: a run dir with a checkpoint (config, frames, finished, run_id) and, if ``results``, a results.json
    written before the trainer saved the config."""
    cfg = profile_config("quick", "easy", {"results_root": str(root / "results"), "table": "t"}, **fields)
    folder = root / "runs" / "t" / run_name(cfg)
    folder.mkdir(parents=True)
    payload = {"model": {}, "config": cfg.to_dict(), "frames": 64, "finished": finished, "run_id": "abc"}
    torch.save(payload, folder / "checkpoint.pt")
    if results:
        (folder / "results.json").write_text(json.dumps({"run_name": run_name(cfg), "metrics": {"sgn_test": 0.5}}))
    return folder, cfg


def test_a_finished_runs_config_is_copied_once_into_its_results_json(tmp_path):
    folder, cfg = fixture_run(tmp_path)
    assert saved_config(folder) is None
    assert backfill_config(folder) == "config added from the checkpoint"
    saved = json.loads((folder / "results.json").read_text())
    assert saved["metrics"] == {"sgn_test": 0.5} and saved["config"] == cfg.to_dict() == saved_config(folder)
    assert backfill_config(folder) == "has its config"


def test_a_run_still_training_is_left_alone(tmp_path):
    folder, _ = fixture_run(tmp_path, finished=False, results=False)
    assert backfill_config(folder).startswith("skipped: not finished")
    assert not (folder / "results.json").exists()


def test_a_lost_results_json_is_rebuilt_from_its_results_row_only_when_the_run_ids_match(tmp_path):
    folder, cfg = fixture_run(tmp_path, results=False, seed=2)
    csv = tmp_path / "results" / "t" / "quick.csv"
    csv.parent.mkdir(parents=True)
    row = {"run_name": run_name(cfg), "table": "t", "model": cfg.model, "difficulty": "easy", "aux": False}
    row |= {"seed": 2, "profile": "quick", "frames": 64, "git_sha": "12e0077", "run_id": "other"}
    row |= {"eval_episodes": 100, "tasks": "both", "shaping": True, "sgn_train": 0.25, "sgn_test": 0.5}
    pd.DataFrame([row]).to_csv(csv, index=False)
    assert backfill_config(folder).startswith("skipped: no results.json and no row")
    pd.DataFrame([{**row, "run_id": "abc"}]).to_csv(csv, index=False)
    assert backfill_config(folder).startswith("results.json rebuilt from its row of quick.csv")
    saved = json.loads((folder / "results.json").read_text())
    assert saved["git_sha"] == "12e0077" and saved["seed"] == 2 and saved["aux"] is False
    assert saved["metrics"] == {"sgn_train": 0.25, "sgn_test": 0.5} and "tasks" not in saved
    assert saved["config"] == cfg.to_dict()
    assert run_dirs([tmp_path / "runs"]) == [folder] == run_dirs([folder])
