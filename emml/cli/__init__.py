"""`emml …`: one typer app. Thin: parses arguments, calls the wing that owns the work, prints (or `--json`).

The commands live by group: train.py (train, eval, rescore, transfer, demo), diagnose.py (diagnose, probe-eqa),
tables.py (list, run, campaign), reports.py (report, reports, backfill-config, import-runs, video, visualize) and
tools.py (tasks, models, oracle, bench); common.py holds what they share. They are registered here, in the order
`emml --help` lists them."""

from __future__ import annotations

import typer

from emml.cli import diagnose, reports, tables, tools, train
from emml.cli.common import _fail

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="EMML: reproduce 'Embodied Multimodal Multitask Learning' (Chaplot et al., 2019) on ViZDoom.",
)
tasks_app = typer.Typer(no_args_is_help=True, help="The datasets: instructions and questions with their splits.")
bench_app = typer.Typer(no_args_is_help=True, help="Throughput benchmarks (ratios measured in one run).")
app.add_typer(tasks_app, name="tasks")
app.add_typer(bench_app, name="bench")
visualize_app = typer.Typer(no_args_is_help=True, help="The paper's figures on a checkpoint (emml/report/visualize.py)")
app.add_typer(visualize_app, name="visualize")


@app.callback()
def _check_project_files(
    plugins: list[str] = typer.Option(
        [],
        "--plugin",
        help="A plugin registering models of your own: a .py file, a package folder or a dotted module (repeatable; "
        "added to EMML_PLUGINS for the processes the command starts). README: 'Compare your own model'.",
    ),
) -> None:
    """Every command reads reproduce/profiles.toml: a broken one is named in one line before anything runs; and
    every command first ends the engines that killed emml processes left (emml/envs/engine.py, sweep_orphans).
    Plugins (--plugin, EMML_PLUGINS) load first, so that a bad one is named in one line (emml/models/plugins.py)."""
    import os

    from emml.models.plugins import ENV_VAR, PluginError, add_plugins

    if plugins or os.environ.get(ENV_VAR):
        try:
            add_plugins(plugins)
        except PluginError as e:
            _fail(str(e))
    from emml.config.profiles import ProfileError, load_profiles

    try:
        load_profiles()
    except ProfileError as e:
        _fail(str(e))
    from emml.envs.engine import sweep_orphans

    ended = sweep_orphans()  # engines of emml processes killed with SIGKILL (nothing else could end them)
    if ended:
        typer.secho(f"ended {len(ended)} ViZDoom engines left by killed emml processes: pids {ended}", err=True)


tasks_app.command("show")(tools.tasks_show)
app.command()(tools.oracle)
bench_app.command("env")(tools.bench_env)
bench_app.command("train")(tools.bench_train_cmd)
bench_app.command("alloc")(tools.bench_alloc_cmd)
bench_app.command("workers")(tools.bench_workers_cmd)
app.command()(tools.models)
app.command()(train.train)
app.command("eval")(train.eval_checkpoint)
app.command("rescore")(train.rescore_runs)
app.command()(train.transfer)
app.command()(diagnose.diagnose)
app.command("probe-eqa")(diagnose.probe_eqa_cmd)
visualize_app.command("channels")(reports.visualize_channels)
visualize_app.command("attention")(reports.visualize_attention)
visualize_app.command("house")(reports.visualize_house)
app.command()(reports.video)
app.command()(train.demo)
app.command("list")(tables.list_experiments)
app.command("run")(tables.run_table)
app.command()(tables.campaign)
app.command()(reports.report)
app.command("reports")(reports.reports)
app.command("backfill-config")(reports.backfill_config)
app.command("import-runs")(reports.import_runs_cmd)
