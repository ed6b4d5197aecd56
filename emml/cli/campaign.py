"""`emml campaign run NAME` and `emml campaign status NAME` (emml/experiments/campaign/).

The spelling before these subcommands, `emml campaign NAME [--status]`, still works and is deprecated: it is what a
stopped campaign's resume line, a pinned campaign's re-execution and scripts/gpu-campaign spell, so a command line
printed or scripted before keeps its meaning. `CampaignGroup` reads it as `run NAME` (`status NAME` with --status)
before parsing; `emml campaign --help` and docs/commands.md say it is deprecated."""

from __future__ import annotations

import shlex

import typer
from typer.core import TyperGroup

from emml.cli.common import (
    JSON_HELP,
    RESULTS_ROOT_HELP,
    RUN_ROOT_HELP,
    _echo,
    _fail,
    _use_tcmalloc,
    campaign_argument,
    device_option,
)

LEGACY_DROPPED = ("--pin", "--no-pin")
"""Options the deprecated `emml campaign NAME --status` took and ignored, which `status` does not take."""


def legacy_args(args: list[str], commands, help_names=("--help",)) -> list[str]:
    """The deprecated `NAME [OPTIONS]` as `run NAME [OPTIONS]`, `NAME --status [OPTIONS]` as `status NAME [OPTIONS]`
    (its ignored --pin/--no-pin left out); a subcommand, the help and an empty line as they are. `NAME status` (the
    word in the wrong place) is refused naming both spellings."""
    if not args or args[0] in commands or args[0] in help_names:
        return args
    if len(args) > 1 and args[1] == "status":
        _fail(f"campaign {args[0]!r} 'status': expected `emml campaign run NAME` or `emml campaign status NAME`")
    if "--status" in args:
        return ["status", *(a for a in args if a != "--status" and a not in LEGACY_DROPPED)]
    return ["run", *args]


class CampaignGroup(TyperGroup):
    """`emml campaign`: its subcommands, and the deprecated spelling read as them (`legacy_args`), also when the
    shell completes a line."""

    def parse_args(self, ctx, args: list[str]) -> list[str]:
        return super().parse_args(ctx, legacy_args(args, self.commands, ctx.help_option_names))


app = typer.Typer(
    cls=CampaignGroup,
    no_args_is_help=True,
    help="Train a campaign's runs in its order (`run NAME`), or show where it stands (`status NAME`).",
    epilog="A campaign is reproduce/campaigns/NAME.toml. `emml campaign NAME [--status]` still works but is "
    "deprecated: spell it `emml campaign run NAME` (`status NAME`).",
)


def _step_names(ctx: typer.Context, incomplete: str) -> list[str]:
    """The steps of the campaign named on the line, as the shell completes `--step` (none before a known name). With
    --step last on the line the parse stops short of its value, leaving the name among the unparsed words."""
    from emml.experiments.campaign import list_campaigns, load_campaign

    names = [n for n in (ctx.params.get("name"), *ctx.args) if n in list_campaigns()]
    try:
        steps = load_campaign(names[0]).steps if names else ()
    except ValueError:  # a campaign file that does not load: `emml campaign status NAME` names its error
        return []
    return [s.name for s in steps if s.name.startswith(incomplete)]


def _steps_option(help: str) -> typer.Option:
    return typer.Option([], "--step", autocompletion=_step_names, help=help)


JOBS_HELP = "Concurrent local runs (0: half the cores)."


@app.command("run")
def run(
    name: str = campaign_argument(),
    pin: bool = typer.Option(
        True,
        "--pin/--no-pin",
        help="Train from a git worktree of this commit (.campaign/<sha>), so edits cannot reach it.",
    ),
    jobs: int = typer.Option(0, help=JOBS_HELP),
    device: str = device_option(),
    run_root: str = typer.Option(None, help=RUN_ROOT_HELP),
    results_root: str = typer.Option(None, help=RESULTS_ROOT_HELP),
    steps: list[str] = _steps_option(
        "Only this step (by name, as `emml campaign status` shows it; repeatable); the campaign's order stays."
    ),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Train a campaign's unfinished runs in its order.

    Interrupted runs resume; with --pin (the default) it trains from a git worktree of this commit."""
    from dataclasses import asdict

    from emml.experiments.campaign import (
        check_no_campaign,
        hold_campaign,
        load_campaign,
        resume_command,
        run_campaign,
        run_pinned,
        select_steps,
    )
    from emml.experiments.launch import stopped_line

    try:
        plan = select_steps(load_campaign(name), steps)
    except ValueError as e:
        _fail(str(e))
    if pin:  # re-exec from a worktree of HEAD, writing into this checkout's runs, results and MLflow store
        try:
            check_no_campaign(name)  # before a worktree is made: the lock is taken where it trains, below
            run_pinned(name, steps, jobs, device, run_root, results_root, as_json, log=typer.echo)
        except ValueError as e:
            _fail(str(e))
    _use_tcmalloc()
    try:
        with hold_campaign(name):  # one campaign per checkout: two would log every run twice to MLflow
            reports = run_campaign(plan, run_root, results_root, device=device, jobs=jobs or None, log=typer.echo)
    except ValueError as e:
        _fail(str(e))
    failed = {k: v for r in reports for k, v in r.failed.items()}
    if reports and reports[-1].stopped:
        from emml.models.plugins import configured

        again = shlex.join(resume_command(name, steps, jobs, device, run_root, results_root, configured()))
        _echo([asdict(r) for r in reports], as_json, stopped_line(reports[-1], again))
        raise typer.Exit(130)
    _echo(
        [asdict(r) for r in reports],
        as_json,
        f"{name}: {sum(len(r.done) for r in reports)} trained, {sum(len(r.skipped) for r in reports)} already "
        f"finished, {len(failed)} failed"
        + (f", {busy} trained by another process" if (busy := sum(len(r.busy) for r in reports)) else ""),
    )
    if failed:
        raise typer.Exit(1)


@app.command("status")
def status(
    name: str = campaign_argument(),
    jobs: int = typer.Option(0, help=JOBS_HELP + " The time left is estimated for this many at a time."),
    device: str = device_option(),
    run_root: str = typer.Option(None, help=RUN_ROOT_HELP),
    results_root: str = typer.Option(None, help=RESULTS_ROOT_HELP),
    steps: list[str] = _steps_option("Only this step (by name; repeatable)."),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Each step's claims and cost, and each run as done / running / interrupted / to do with the time left.

    The time left is measured from this machine's own runs of the same model and profile; trains nothing."""
    from dataclasses import asdict

    from emml.experiments.campaign import load_campaign, runs_at_once, select_steps, status_text
    from emml.experiments.campaign import status as campaign_status

    try:
        plan = select_steps(load_campaign(name), steps)
        rows = campaign_status(plan, run_root, results_root)
        at_once = runs_at_once(jobs, device)
    except ValueError as e:
        _fail(str(e))
    _echo([asdict(r) for r in rows], as_json, status_text(plan, rows, at_once, device))
