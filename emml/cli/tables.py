"""The tables and campaigns: `emml list`, `emml run` and `emml campaign` (emml/experiments/)."""

from __future__ import annotations

import shlex

import typer

from emml.cli.common import (
    JSON_HELP,
    RESULTS_ROOT_HELP,
    RUN_ROOT_HELP,
    Backend,
    SlurmCluster,
    _echo,
    _fail,
    _use_tcmalloc,
    device_option,
    profile_option,
)


def list_experiments(
    profile: str = profile_option(help="Whose results count as finished."),
    run_root: str = typer.Option(None, help=RUN_ROOT_HELP),
    results_root: str = typer.Option(None, help=RESULTS_ROOT_HELP),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Every table with its runs, and which are finished under the profile."""
    from emml.experiments.launch import run_states
    from emml.experiments.table_files import list_tables
    from emml.experiments.tables import load_table

    data, lines = [], []
    for name in list_tables():
        try:
            table = load_table(name)
            states = run_states(name, profile, run_root, results_root)
        except ValueError as e:
            _fail(str(e))
        runs = [{"run_name": rname, "row": spec.row, "state": state} for rname, (spec, state) in states.items()]
        finished = sum(r["state"] in ("finished", "unrecorded") for r in runs)
        data.append(
            {
                "table": name,
                "status": table.status,
                "title": table.title,
                "finished": finished,
                "total": len(runs),
                "runs": runs,
            }
        )
        head = f"{name} ({table.paper_label}): {table.status}"
        lines.append(head + ("" if table.placeholder else f", {finished}/{len(runs)} runs finished [{profile}]"))
        lines += [f"  {r['state']:<10} {r['run_name']}" for r in runs]
    _echo({"profile": profile, "tables": data}, as_json, "\n".join(lines))


def run_table(
    table: str = typer.Argument(
        ...,
        help="table2 | table3 | table4 | table5 (reproduce/<table>.toml), experiments/<name> "
        "(reproduce/experiments/<name>.toml), or a table file of your own (x.toml).",
    ),
    profile: str = profile_option(),
    backend: Backend = typer.Option(
        "local", help="local: a process pool here; slurm: submitit jobs of --pack runs each, requeued at their limit."
    ),
    jobs: int = typer.Option(0, help="Concurrent local runs (0: half the cores; cuda: and what GPU memory holds)."),
    device: str = device_option(),
    run_root: str = typer.Option(None, help=RUN_ROOT_HELP),
    results_root: str = typer.Option(None, help=RESULTS_ROOT_HELP),
    partition: str = typer.Option(None, help="Slurm partition."),
    time_min: int = typer.Option(24 * 60, help="Slurm time limit per job, minutes (then it saves and requeues)."),
    gpus: int = typer.Option(0, help="GPUs per Slurm job."),
    cpus: int = typer.Option(8, help="CPUs per Slurm job (shared by its --pack runs)."),
    pack: int = typer.Option(1, min=1, help="Slurm: runs per job, side by side on its GPU (e.g. 8 on one H100)."),
    wait: bool = typer.Option(False, help="Slurm: wait for the jobs to end."),
    slurm_cluster: SlurmCluster = typer.Option(
        "slurm",
        help="Slurm: where the jobs run. local: submitit's local executor, a job process here with Slurm's time "
        "limit and requeue (try the Slurm path without a cluster); debug: in this process.",
    ),
    only: list[str] = typer.Option(
        [], "--only", help="Only the runs whose FIELD=VALUE (row, model, difficulty, aux, seed), e.g. difficulty=easy."
    ),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Train every run of a table.

    Finished runs are skipped, interrupted ones resume; a placeholder table (no runs declared yet) exits 0."""
    from dataclasses import asdict

    from emml.experiments.launch import run_table as launch
    from emml.experiments.launch import stopped_line
    from emml.experiments.tables import load_table

    selection = {}
    for item in only:
        key, sep, value = item.partition("=")
        if not sep:
            _fail(f"--only {item!r}: expected FIELD=VALUE, e.g. --only difficulty=easy")
        selection[key.strip()] = value.strip()
    try:
        loaded = load_table(table)  # a .toml path: its name is the file's stem (emml.experiments.table_files.own_table)
    except ValueError as e:
        _fail(str(e))
    if backend == "local" and not loaded.placeholder:
        _use_tcmalloc()  # ~2x CPU training speed; the pool's workers inherit LD_PRELOAD
    try:
        report = launch(
            loaded.name,
            profile,
            backend=backend,
            jobs=jobs or None,
            run_root=run_root,
            results_root=results_root,
            device=device,
            partition=partition,
            time_min=time_min,
            pack=pack,
            gpus=gpus,
            cpus=cpus,
            wait=wait,
            slurm_cluster=slurm_cluster,
            log=(lambda m: None) if as_json else typer.echo,
            only=selection,
        )
    except ValueError as e:
        _fail(str(e))
    data = asdict(report)
    if report.stopped:
        from emml.experiments.resume import command_line
        from emml.models.plugins import configured

        options = [("--profile", profile), ("--run-root", run_root), ("--results-root", results_root)]
        options += [("--only", only), ("--jobs", jobs), ("--device", device if device != "cpu" else None)]
        if backend == "slurm":  # the same jobs' shape: a rerun resumes them there
            options += [("--backend", "slurm"), ("--partition", partition), ("--time-min", time_min)]
            options += [("--gpus", gpus), ("--cpus", cpus), ("--pack", pack), ("--wait", wait)]
            options += [("--slurm-cluster", slurm_cluster if slurm_cluster != "slurm" else None)]
        # quoted for the shell: a row label has spaces ("--only 'row=softplus, mean'"); a model of one's own needs
        # its plugin
        again = shlex.join(command_line(["run", table], options, configured()))
        _echo(data, as_json, stopped_line(report, again))
        raise typer.Exit(130)
    _echo(
        data,
        as_json,
        f"{table} [{profile}]: {len(report.done)} trained, {len(report.skipped)} already finished, "
        f"{len(report.failed)} failed"
        + (f", {len(report.busy)} trained by another process" if report.busy else "")
        + (f", {len(report.submitted)} jobs submitted" if report.submitted else ""),
    )
    if report.failed:
        raise typer.Exit(1)


def campaign(
    name: str = typer.Argument(
        ...,
        metavar="NAME|status",
        help="A campaign of reproduce/campaigns/ (e.g. reference), or `status` followed by one: its status.",
    ),
    of: str = typer.Argument(None, metavar="NAME", help="After `status`: the campaign whose status is shown."),
    show_status: bool = typer.Option(
        False, "--status", help="Show each run as done / running / interrupted / to do (`emml campaign status NAME`)."
    ),
    pin: bool = typer.Option(
        True,
        "--pin/--no-pin",
        help="Train from a git worktree of this commit (.campaign/<sha>), so edits cannot reach it.",
    ),
    jobs: int = typer.Option(0, help="Concurrent local runs (0: half the cores)."),
    device: str = device_option(),
    run_root: str = typer.Option(None, help=RUN_ROOT_HELP),
    results_root: str = typer.Option(None, help=RESULTS_ROOT_HELP),
    steps: list[str] = typer.Option(
        [], "--step", help="Only this step (by name, as --status shows it; repeatable); the campaign's order stays."
    ),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Train a campaign's unfinished runs in its order, or show its status (`emml campaign status NAME`).

    Interrupted runs resume; with --pin (the default) it trains from a git worktree of this commit."""
    from dataclasses import asdict

    from emml.experiments.campaign import (
        check_no_campaign,
        hold_campaign,
        load_campaign,
        resume_command,
        run_campaign,
        run_pinned,
        runs_at_once,
        select_steps,
        status,
        status_text,
    )
    from emml.experiments.launch import stopped_line

    if of is not None:  # `emml campaign status NAME`: the same as `emml campaign NAME --status`
        if name != "status":
            _fail(f"campaign {name!r} {of!r}: expected `emml campaign NAME` or `emml campaign status NAME`")
        name, show_status = of, True
    try:
        plan = select_steps(load_campaign(name), steps)
    except ValueError as e:
        _fail(str(e))
    if show_status:
        try:
            rows = status(plan, run_root, results_root)
            at_once = runs_at_once(jobs, device)
        except ValueError as e:
            _fail(str(e))
        _echo([asdict(r) for r in rows], as_json, status_text(plan, rows, at_once, device))
        return
    if pin:  # re-exec from a worktree of HEAD, writing into this checkout's runs, results and MLflow store
        try:
            check_no_campaign(name)  # before a worktree is made: the lock is taken where it trains, below
            run_pinned(name, steps, jobs, device, run_root, results_root, as_json, log=typer.echo)
        except ValueError as e:
            _fail(str(e))
    _use_tcmalloc()
    try:
        with hold_campaign(name):  # one campaign per checkout (issue 54: two doubled every run's MLflow entries)
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
