"""`emml …`: one typer app. Thin: parses arguments, calls the wing that owns the work, prints (or `--json`).

The commands live by group: train.py (train, eval, rescore, transfer, demo), diagnose.py (diagnose, probe-eqa),
tables.py (list, run), campaign.py (campaign run, campaign status), reports.py (report, reports, backfill-config,
import-runs, video, visualize) and tools.py (tasks, models, oracle, bench); common.py holds what they share. They are
registered here under the groups (`rich_help_panel`) and in the order `emml --help` lists them; `emml
--install-completion` completes commands, options, their choices and the names of tables, campaigns and models in
the shell."""

from __future__ import annotations

import typer

from emml.cli import campaign, diagnose, reports, tables, tools, train
from emml.cli.common import _fail

TRAIN, SCORE, REPORTS, TOOLS = "Train", "Evaluate & diagnose", "Tables & reports", "Tools"
"""The groups `emml --help` lists the commands in."""

app = typer.Typer(
    add_completion=True,
    no_args_is_help=True,
    help="EMML: reproduce 'Embodied Multimodal Multitask Learning' (Chaplot et al., 2019) on ViZDoom.",
)
tasks_app = typer.Typer(no_args_is_help=True, help="The datasets: instructions and questions by split.")
bench_app = typer.Typer(no_args_is_help=True, help="Throughput benchmarks, measured as ratios in one run.")
visualize_app = typer.Typer(no_args_is_help=True, help="The paper's figures on a checkpoint.")
app.add_typer(campaign.app, name="campaign", rich_help_panel=TRAIN)
app.add_typer(tasks_app, name="tasks", rich_help_panel=TOOLS)
app.add_typer(bench_app, name="bench", rich_help_panel=TOOLS)
app.add_typer(visualize_app, name="visualize", rich_help_panel=REPORTS)


@app.callback()
def _check_project_files(
    plugins: list[str] = typer.Option(
        [],
        "--plugin",
        help="A plugin registering models of your own: a .py file, a package folder or a dotted module (repeatable; "
        "every process the command starts loads it too).",
    ),
) -> None:
    """EMML: reproduce 'Embodied Multimodal Multitask Learning' (Chaplot et al., 2019) on ViZDoom.

    Before any command: plugins load (a bad one is named in one line), the profiles file is read (a broken one is
    named in one line), and the ViZDoom engines that killed emml processes left are ended."""
    import os

    from emml.config.paths import PLUGINS_ENV_VAR

    if plugins or os.environ.get(PLUGINS_ENV_VAR):  # the model zoo (torch) imported only for plugins to add
        from emml.models.plugins import PluginError, add_plugins

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


# in the order `emml --help` lists them, group by group
app.command(rich_help_panel=TRAIN)(train.train)
app.command(rich_help_panel=TRAIN)(train.demo)
app.command("run", rich_help_panel=TRAIN)(tables.run_table)
app.command("list", rich_help_panel=TRAIN)(tables.list_experiments)
app.command("eval", rich_help_panel=SCORE)(train.eval_checkpoint)
app.command("rescore", rich_help_panel=SCORE)(train.rescore_runs)
app.command(rich_help_panel=SCORE)(train.transfer)
app.command(rich_help_panel=SCORE)(diagnose.diagnose)
app.command("probe-eqa", rich_help_panel=SCORE)(diagnose.probe_eqa_cmd)
app.command(rich_help_panel=REPORTS)(reports.report)
app.command("reports", rich_help_panel=REPORTS)(reports.reports)
app.command(rich_help_panel=REPORTS)(reports.video)
app.command("import-runs", rich_help_panel=REPORTS)(reports.import_runs_cmd)
app.command("backfill-config", rich_help_panel=REPORTS)(reports.backfill_config)
visualize_app.command("channels")(reports.visualize_channels)
visualize_app.command("attention")(reports.visualize_attention)
visualize_app.command("house")(reports.visualize_house)
tasks_app.command("show")(tools.tasks_show)
app.command(rich_help_panel=TOOLS)(tools.models)
app.command(rich_help_panel=TOOLS)(tools.oracle)
bench_app.command("env")(tools.bench_env)
bench_app.command("train")(tools.bench_train_cmd)
bench_app.command("alloc")(tools.bench_alloc_cmd)
bench_app.command("workers")(tools.bench_workers_cmd)
