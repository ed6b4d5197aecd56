"""The tables: `emml list` and `emml run` (emml/experiments/); campaigns are campaign.py's."""

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
    table_argument,
)


def list_experiments(
    profile: str = profile_option(help="Whose results count as finished."),
    run_root: str = typer.Option(None, help=RUN_ROOT_HELP),
    results_root: str = typer.Option(None, help=RESULTS_ROOT_HELP),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Every table with its runs, and which are finished under the profile."""
    from emml.experiments.plan import run_states
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
    table: str = table_argument(
        "table2 | table3 | table4 | table5 (reproduce/<table>.toml), experiments/<name> "
        "(reproduce/experiments/<name>.toml), or a table file of your own (x.toml)."
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
