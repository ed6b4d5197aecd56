"""The table page's footnote on the commits its runs trained under (issue 60): each run trained under more than one
commit, with each commit's frames, read from its results.json's ``segments`` (emml/runs/segments.py)."""

from __future__ import annotations

import json
from pathlib import Path

from emml.runs.rundir import RESULTS, path_of
from emml.runs.segments import commits, describe, read_run_segments


def commits_note(results, names: list[str], run_root: str | Path) -> list[str]:
    """The table page's footnote on the commits its runs trained under: each run of ``names`` trained under more than
    one commit, with each commit's frames (its results.json under ``run_root``, its table the results row's), and how
    many runs record only the commit that finished them (run dirs from before segments, or absent here); [] when
    ``names`` is empty."""
    if not names:
        return []
    rows = {r["run_name"]: r for r in results.to_dict("records")} if not results.empty else {}
    several, last_only = [], 0
    for name in names:
        row = rows.get(name, {})
        path = path_of(run_root, str(row.get("table") or ""), name) / RESULTS
        try:
            payload = json.loads(path.read_text()) if row.get("table") and path.exists() else row
        except (OSError, ValueError):  # a damaged results.json is named by the readers of the config; here: the row
            payload = row
        segments, recorded = read_run_segments(payload if isinstance(payload, dict) else row)
        last_only += not recorded
        if len(commits(segments)) > 1:
            several.append(f"`{name}`: {describe(segments)}")
    parts = []
    if several:
        parts.append(f"trained under several commits (each commit's frames): {'; '.join(several)}.")
    if last_only:
        parts.append(
            f"{last_only} of {len(names)} runs record only the commit that finished them (the results CSV's "
            "`git_sha`): they were trained before each session's commit was recorded."
        )
    elif not several:
        parts.append("each run trained under one commit (its results.json `segments`; the results CSV's `git_sha`).")
    return [f"**Commits**: {' '.join(parts)}", ""]
