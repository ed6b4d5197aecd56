"""The table page's footnote on the commits its runs trained under (issue 60): each run trained under more than one
commit, with each commit's frames, read from its results.json's ``segments`` (emml/runs/segments.py)."""

from __future__ import annotations

import json

from emml.experiments.plan import PlannedRun
from emml.runs.rundir import RESULTS
from emml.runs.segments import commits, describe, read_run_segments


def commits_note(results, runs: list[PlannedRun]) -> list[str]:
    """The table page's footnote on the commits its runs trained under: each planned run of ``runs`` trained under
    more than one commit, with each commit's frames (the results.json in its run dir, else its results row), and how
    many runs record only the commit that finished them (run dirs from before segments, or absent here); [] when
    ``runs`` is empty."""
    if not runs:
        return []
    rows = {r["run_name"]: r for r in results.to_dict("records")} if not results.empty else {}
    several, last_only = [], 0
    for run in runs:
        row = rows.get(run.name, {})
        path = run.directory / RESULTS
        try:
            payload = json.loads(path.read_text()) if path.exists() else row
        except (OSError, ValueError):  # a damaged results.json is named by the readers of the config; here: the row
            payload = row
        segments, recorded = read_run_segments(payload if isinstance(payload, dict) else row)
        last_only += not recorded
        if len(commits(segments)) > 1:
            several.append(f"`{run.name}`: {describe(segments)}")
    parts = []
    if several:
        parts.append(f"trained under several commits (each commit's frames): {'; '.join(several)}.")
    if last_only:
        parts.append(
            f"{last_only} of {len(runs)} runs record only the commit that finished them (the results CSV's "
            "`git_sha`): they were trained before each session's commit was recorded."
        )
    elif not several:
        parts.append("each run trained under one commit (its results.json `segments`; the results CSV's `git_sha`).")
    return [f"**Commits**: {' '.join(parts)}", ""]
