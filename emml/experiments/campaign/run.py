"""Running a campaign: its steps in order through the table launcher (`run_campaign`), from a git worktree of the
current commit (`pin_worktree`, `run_pinned`), and the command that resumes it (`resume_command`)."""

from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

from emml.config.paths import PIN_DIR, checkout_root, project_path, project_root
from emml.experiments.campaign.file import CAMPAIGNS_DIR, Campaign
from emml.experiments.resume import command_line
from emml.runs.runlock import waiting_lock


def run_campaign(
    campaign: Campaign,
    run_root: str | None = None,
    results_root: str | None = None,
    device: str = "cpu",
    jobs: int | None = None,
    log: Callable[[str], None] = print,
    train_fn: Callable | None = None,
) -> list:
    """Train every step's unfinished runs, step by step in the campaign's order (emml.experiments.launch.run_table per
    step); returns the steps' LaunchReports. A failed run is reported and the campaign goes on, as a table does; a stop
    (Ctrl-C, SIGTERM) ends it after the step it stopped (its report's `stopped`)."""
    from emml.experiments.launch import run_table

    reports = []
    for i, step in enumerate(campaign.steps, 1):
        log(f"[{campaign.name} {i}/{len(campaign.steps)}] {step.name}: {step.table} [{step.profile}]")
        reports.append(
            run_table(
                step.table,
                step.profile,
                jobs=jobs,
                run_root=run_root,
                results_root=results_root,
                device=device,
                log=log,
                only=step.only,
                overrides=step.overrides(),
                train_fn=train_fn,
            )
        )
        if reports[-1].stopped:  # Ctrl-C / SIGTERM: no further step starts
            break
    return reports


def pin_worktree(root: Path, log: Callable[[str], None] = print, need: Path | None = None) -> Path:
    """A git worktree of `root`'s HEAD at <root>/.campaign/<sha>/ (made once per commit); uncommitted changes are not
    in it, and a warning says so. ``need``: a file (under ``root``) the campaign reads, which must be committed
    (a ValueError says to commit it). Concurrent starts make the worktree once (a lock around `git worktree add`),
    and one left half-made by a kill is made again."""

    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, check=True).stdout.strip()

    try:
        sha = git("rev-parse", "HEAD")
    except (OSError, subprocess.CalledProcessError) as e:
        raise ValueError(f"{root} is not a git checkout ({e}); run the campaign with --no-pin") from None
    if need is not None:
        relative = Path(need).resolve().relative_to(Path(root).resolve()).as_posix()
        try:
            git("cat-file", "-e", f"HEAD:{relative}")
        except subprocess.CalledProcessError:
            raise ValueError(
                f"{relative} is not committed: the campaign trains commit {sha[:7]} from a worktree of it "
                f"({PIN_DIR}/{sha[:12]}), which does not have it; commit it (git add {relative}; git commit), or run "
                "with --no-pin"
            ) from None
    if git("status", "--porcelain", "--untracked-files=no"):
        log(f"warning: uncommitted changes in {root} are not in the campaign's code (it runs commit {sha[:7]})")
    tree = root / PIN_DIR / sha[:12]
    (root / PIN_DIR).mkdir(exist_ok=True)
    with waiting_lock(root / PIN_DIR / "pin.lock"):  # a second start waits for the first's `git worktree add`
        if not (tree / "pyproject.toml").exists():
            if tree.exists():  # half-made by a killed start: git refuses to add over it
                shutil.rmtree(tree)
            subprocess.run(["git", "worktree", "prune"], cwd=root, capture_output=True)
            git("worktree", "add", "--detach", str(tree), sha)
    return tree


def run_pinned(
    name: str,
    steps: list[str],
    jobs: int = 0,
    device: str = "cpu",
    run_root: str | None = None,
    results_root: str | None = None,
    as_json: bool = False,
    log: Callable[[str], None] = print,
) -> None:
    """Re-execute `emml campaign NAME --no-pin` (the same steps and options: `resume_command`) from a worktree of HEAD
    (`pin_worktree`), writing into this checkout's runs, results and MLflow store; does not return. A checkout that is
    no git one is a ValueError."""
    import sys

    from emml.runs.store import tracking_uri

    root = project_root()
    tree = pin_worktree(root, log=log, need=CAMPAIGNS_DIR / f"{name}.toml")
    # roots given are passed as absolute paths; the others resolve under this checkout there too
    # (emml.config.paths.checkout_root), each step's profile choosing its own (smoke: scratch/)
    again = resume_command(name, steps, jobs, device, run_root, results_root, pinned=False)
    args = [sys.executable, "-m", "emml.cli", *again[1:], *(["--json"] if as_json else [])]
    env = {**os.environ, "PYTHONPATH": str(tree), "MLFLOW_TRACKING_URI": tracking_uri()}
    log(f"{name}: training from {tree} (commit {tree.name})")
    os.chdir(tree)  # `python -m` puts the working directory first on sys.path: the tree's emml, not this one's
    os.execve(sys.executable, args, env)


def resume_command(
    name: str,
    steps: list[str],
    jobs: int = 0,
    device: str = "cpu",
    run_root: str | None = None,
    results_root: str | None = None,
    plugins: list[str] = (),
    pinned: bool | None = None,
) -> list[str]:
    """The command that resumes a stopped campaign: every option that changes what is resumed (the steps, the
    roots, as absolute paths, where and how many runs at a time, the plugins its models need), and --no-pin when it
    did not run from a pinned worktree (issue 54: a resume line without the roots started new runs instead).
    ``pinned``: whether it runs pinned; None: whether this process runs from <checkout>/.campaign/<sha>."""
    if pinned is None:
        pinned = checkout_root() != project_root()
    options = [
        ("--step", steps),
        ("--jobs", jobs),
        ("--device", device if device != "cpu" else None),
        ("--run-root", run_root and project_path(run_root)),
        ("--results-root", results_root and project_path(results_root)),
        ("--no-pin", not pinned),
    ]
    return command_line(["campaign", "run", name], options, plugins)
