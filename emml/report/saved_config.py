"""Where a report reads the config a run trained with: its results.json ("config", `TrainConfig.to_dict()`, written
by the trainer), so that reports need no checkpoint. `backfill_config` copies it once from the checkpoint into the
results.json of a run finished before the trainer wrote it (`emml backfill-config RUN_DIR...`)."""

from __future__ import annotations

import json
from pathlib import Path

from emml.runs.rundir import CHECKPOINT, RESULTS, ROW_ONLY
from emml.runs.rundir import write_json as _write


def _is_metric(column: str) -> bool:
    from emml.eval.metrics import is_metric

    return is_metric(column)


def _payload_from_row(row: dict) -> dict:
    """results.json rebuilt from its results CSV row (`record_result` writes the payload's keys but "metrics", then
    `ROW_ONLY`, then the metrics): the keys in the row's order, then "metrics" (empty cells dropped)."""
    payload = {k: v for k, v in row.items() if not _is_metric(k) and k not in ROW_ONLY and not _blank(v)}
    payload["metrics"] = {k: v for k, v in row.items() if _is_metric(k) and not _blank(v)}
    return payload


def _blank(value) -> bool:
    import pandas as pd

    return value is None or bool(pd.isna(value))


def backfill_config(run_dir: Path) -> str:
    """Write the checkpoint's config into the run's results.json when it has none; returns what was done.

    Only a finished checkpoint is read (a run still training writes its own results.json at the end). A finished
    run whose results.json is missing gets it rebuilt from its row of the results CSV when the row's run_id is the
    checkpoint's (the row is the payload, flattened)."""
    from emml.config.paths import project_path
    from emml.runs.checkpoint import load_checkpoint
    from emml.runs.results import read_results

    run_dir = Path(run_dir)
    path = run_dir / RESULTS
    if path.exists() and "config" in json.loads(path.read_text()):
        return "has its config"
    if not (run_dir / CHECKPOINT).exists():
        return "skipped: no checkpoint"
    saved = load_checkpoint(run_dir / CHECKPOINT)
    if not saved.get("finished"):
        return "skipped: not finished (its trainer writes results.json with the config)"
    config = saved["config"]
    if path.exists():
        payload = json.loads(path.read_text())
        payload["config"] = config
        _write(path, payload)
        return "config added from the checkpoint"
    csv = project_path(config.get("results_root", "results")) / config["table"] / f"{config['profile']}.csv"
    rows = read_results(csv)
    row = rows[rows["run_name"] == run_dir.name] if not rows.empty else rows
    if row.empty or row.iloc[0]["run_id"] != saved.get("run_id"):
        return f"skipped: no results.json and no row of {run_dir.name} with its run_id in {csv}"
    record = {k: (v.item() if hasattr(v, "item") else v) for k, v in row.iloc[0].to_dict().items()}
    _write(path, {**_payload_from_row(record), "config": config})
    return f"results.json rebuilt from its row of {csv.name} (run_id {saved['run_id']}), config from the checkpoint"


def run_dirs(paths: list[Path]) -> list[Path]:
    """Every run dir (a folder holding checkpoint.pt) at or under ``paths``, sorted."""
    out = set()
    for p in map(Path, paths):
        if (p / CHECKPOINT).exists():
            out.add(p)
        else:
            out.update(c.parent for c in p.rglob(CHECKPOINT))
    return sorted(out)
