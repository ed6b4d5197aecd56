"""One campaign per checkout: the lock a campaign holds while it trains into the checkout's runs, results and MLflow
store (two would share them: issue 54, each run's MLflow entries doubled)."""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

from emml.config.paths import PIN_DIR, checkout_root

LOCK = "campaign.lock"
"""Under <checkout>/.campaign/: held (flock) by the one campaign training into the checkout (`hold_campaign`)."""


class CampaignRunning(ValueError):
    """Another campaign trains into this checkout (the message names its pid)."""


def campaign_lock_path() -> Path:
    """The checkout's campaign lock: one per checkout, whichever worktree the campaign runs from."""
    return checkout_root() / PIN_DIR / LOCK


def _refusal(name: str, info: dict) -> CampaignRunning:
    from emml.runs.runlock import describe

    return CampaignRunning(
        f"campaign {info.get('campaign', '?')!r} is already training into {checkout_root()}: {describe(info)}; one "
        f"campaign per checkout at a time (two would share its runs, results and MLflow store): wait for it to end "
        f"or stop it (kill {info.get('pid', '?')}), then run `emml campaign {name}` again"
    )


def check_no_campaign(name: str) -> None:
    """CampaignRunning when a live campaign holds the checkout's lock: said before a worktree is made or anything
    starts (the lock itself is taken by `hold_campaign`, in the process that trains)."""
    from emml.runs.runlock import lock_holder

    info = lock_holder(campaign_lock_path())
    if info is not None:
        raise _refusal(name, info)


@contextmanager
def hold_campaign(name: str):
    """Hold the checkout's campaign lock while the block runs; CampaignRunning (before anything starts) when another
    live campaign holds it. flock: the kernel releases it however the holder ends (`kill -9` included)."""
    from emml.runs.runlock import lock_holder, take_lock

    path = campaign_lock_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = take_lock(path, campaign=name)
    if fd is None:
        raise _refusal(name, lock_holder(path) or {})
    try:
        yield
    finally:
        os.close(fd)
