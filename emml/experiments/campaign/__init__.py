"""Campaigns: an ordered, resumable list of table runs (reproduce/campaigns/<name>.toml).

A campaign file lists `[[steps]]` in the order they are to be trained; a step names a table, a profile, which of
the table's runs (`only`: RunSpec fields, each one value or a list whose order orders the runs) and, optionally,
`frames` (a step may train a profile to fewer frames than the profile's, e.g. the paper profile's first 1.5M) and
`set` (how its runs are measured: TrainConfig.RUNTIME fields such as eval_every, which never change what a run is or
its name, e.g. the paper profile's first curve evaluated every 100k frames rather than every 500k). A step's
table is one of the paper's (reproduce/table*.toml) or an experiment beyond them, `experiments/<name>`
(reproduce/experiments/<name>.toml: a table of one's own, `emml run FILE`, whose rows are the settings an issue
measures, e.g. issue 34's x_sent readout).
`emml campaign NAME` trains every unfinished run in that order through the table launcher
(emml/experiments/launch.py), which skips finished runs and resumes interrupted ones; `emml campaign status NAME` (or
`emml campaign NAME --status`) shows each run as done / running / interrupted / to do with its frames and an estimate
of the time left, measured from this machine's own runs of the same profile.

A run is "running" while a live process holds its lock (emml/runs/runlock.py). A campaign is long: `emml campaign`
runs it from a git worktree of the current commit (`pin_worktree`), so that editing the checkout cannot reach a
running training and every row it writes keeps that commit's sha; the runs, results and MLflow store stay the
checkout's.

The package, one concern a module: the campaign file and its steps' runs (file.py), the status and time left
(progress.py), the one-campaign-per-checkout lock (lock.py), and running it, pinned to a worktree, with its resume line
(run.py). Every name is importable from here, as callers import it.
"""

from emml.experiments.campaign.file import (
    CAMPAIGNS_DIR,
    OWN_KEYS,
    STEP_KEYS,
    TOP_KEYS,
    Campaign,
    Step,
    list_campaigns,
    load_campaign,
    select_steps,
    step_runs,
)
from emml.experiments.campaign.lock import LOCK, CampaignRunning, campaign_lock_path, check_no_campaign, hold_campaign
from emml.experiments.campaign.progress import (
    NODE_FPS,
    NODE_RUNS,
    STATES,
    RunStatus,
    runs_at_once,
    status,
    status_text,
    wall_seconds,
)
from emml.experiments.campaign.run import pin_worktree, resume_command, run_campaign, run_pinned

__all__ = [
    "CAMPAIGNS_DIR",
    "LOCK",
    "NODE_FPS",
    "NODE_RUNS",
    "OWN_KEYS",
    "STATES",
    "STEP_KEYS",
    "TOP_KEYS",
    "Campaign",
    "CampaignRunning",
    "RunStatus",
    "Step",
    "campaign_lock_path",
    "check_no_campaign",
    "hold_campaign",
    "list_campaigns",
    "load_campaign",
    "pin_worktree",
    "resume_command",
    "run_campaign",
    "run_pinned",
    "runs_at_once",
    "select_steps",
    "status",
    "status_text",
    "step_runs",
    "wall_seconds",
]
