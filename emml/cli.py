"""`emml …`: one typer app. Thin: parses arguments, calls the library, prints (or `--json`)."""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import typer

from emml.env_kinds import DOOM_ID, ENV_KINDS, GYM_ENVS, kinds_of
from emml.runs import run_name

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


def _fail(message: str) -> None:
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    raise typer.Exit(2)


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
    Plugins (--plugin, EMML_PLUGINS) load first, so that a bad one is named in one line (emml/plugins.py)."""
    import os

    from emml.plugins import ENV_VAR, PluginError, add_plugins

    if plugins or os.environ.get(ENV_VAR):
        try:
            add_plugins(plugins)
        except PluginError as e:
            _fail(str(e))
    from emml.profiles import ProfileError, load_profiles

    try:
        load_profiles()
    except ProfileError as e:
        _fail(str(e))
    from emml.envs.engine import sweep_orphans

    ended = sweep_orphans()  # engines of emml processes killed with SIGKILL (nothing else could end them)
    if ended:
        typer.secho(f"ended {len(ended)} ViZDoom engines left by killed emml processes: pids {ended}", err=True)


def _check_checkpoint(path: Path) -> None:
    """Fail with one line naming the path unless it holds an emml checkpoint (before any engine starts)."""
    from emml.checkpoint import CheckpointError, load_checkpoint

    try:
        load_checkpoint(path)
    except CheckpointError as e:
        _fail(str(e))


def _check_store() -> None:
    """Fail with one line naming the MLflow store unless it answers and takes writes within seconds
    (emml/preflight.py): MLflow itself retries an unreachable store for ~100 s, then prints a traceback."""
    from emml.preflight import check_store

    try:
        check_store()
    except ValueError as e:
        _fail(str(e))


def _out(path: Path) -> Path:
    """An output folder, made; relative paths resolve under the checkout like runs/ and results/ (README)."""
    from emml.tracking import project_path

    path = project_path(path)
    path.mkdir(parents=True, exist_ok=True)
    return path


def _echo(data, as_json: bool, text: str) -> None:
    typer.echo(json.dumps(data, indent=2) if as_json else text)


@tasks_app.command("show")
def tasks_show(
    dataset: str = typer.Argument("doom", help="doom (Table 7) | house (Table 8)"),
    as_json: bool = typer.Option(False, "--json"),
):
    """List a dataset's instructions and questions by task and split."""
    from emml.tasks.language import KINDS, SPLITS, Vocabulary, load_dataset

    try:
        ds = load_dataset(dataset)
    except ValueError as e:
        _fail(str(e))
    data = {
        "dataset": ds.name,
        "vocabulary": list(Vocabulary.from_dataset(ds).words),
        "actors": {n: {"words": list(a.words()), "area": a.area} for n, a in ds.actors.items()},
    }
    lines = []
    for kind in KINDS:
        for split in SPLITS:
            sents = ds.select(kind, split)
            data[f"{kind}_{split}"] = [s.text for s in sents]
            lines.append(f"{kind.upper()} {split} ({len(sents)}):")
            lines += [f"  {s.text}" for s in sents]
    _echo(data, as_json, "\n".join(lines))


_ENV_HELP = " | ".join(e.name for e in GYM_ENVS.values()) + " (house: the House domain, Appendix C)"
_DOOM_DIFFICULTY_HELP = " | ".join(kinds_of(DOOM_ID)) + " (doom only)"
_DIFFICULTY_HELP = " | ".join(ENV_KINDS) + " (house: the House domain, Appendix C)"


def _gym_id(env_name: str) -> str:
    """The gym id of an ``--env`` name (emml/env_kinds.py), or fail naming the allowed names."""
    ids = {e.name: e.gym_id for e in GYM_ENVS.values()}
    if env_name not in ids:
        _fail(f"--env={env_name!r} is not allowed; choose one of {', '.join(map(repr, ids))}")
    return ids[env_name]


def _env_config(gym_id: str, difficulty: str, **fields):
    """(difficulty, validated config) of the env ``gym_id``: an env that plays one kind (the House) plays it
    whatever ``difficulty`` says; a bad value fails with the field's name."""
    from emml.config import ENV_CONFIGS

    kinds = kinds_of(gym_id)
    if len(kinds) == 1:
        difficulty = kinds[0]
    try:
        return difficulty, ENV_CONFIGS[gym_id](difficulty=difficulty, **fields).validate()
    except ValueError as e:
        _fail(str(e))


@app.command()
def oracle(
    env_name: str = typer.Option("doom", "--env", help=_ENV_HELP),
    difficulty: str = typer.Option("easy", help=_DOOM_DIFFICULTY_HELP),
    task: str = typer.Option("sgn", help="sgn | eqa | both"),
    split: str = typer.Option("train", help="train | test"),
    episodes: int = typer.Option(100, min=1),
    seed: int = 0,
    height: int = 168,
    width: int = 300,
    as_json: bool = typer.Option(False, "--json"),
    video: Path = typer.Option(None, help="Also record a few Easy and Hard episodes as a GIF in this folder."),
):
    """Accuracy of the scripted expert (privileged state): every episode must be solvable."""
    from emml.agents.oracle import run_oracle
    from emml.envs.vector import make_env

    _own_engines()
    gym_id = _gym_id(env_name)
    if video is not None and gym_id != DOOM_ID:
        _fail(f"--video records Doom episodes only; leave it out with --env {env_name}")
    difficulty, cfg = _env_config(gym_id, difficulty, tasks=task, split=split, height=height, width=width)
    env = make_env(cfg)
    try:
        result = run_oracle(env, episodes, seed)
    finally:
        env.close()
    result = {"env": env_name, "difficulty": difficulty, "task": task, "split": split, **result}
    if video is not None:
        from emml.report.oracle_video import oracle_demo

        result["video"] = [str(p) for p in oracle_demo(_out(video), episodes=min(episodes, 3), seed=seed)]
    _echo(
        result,
        as_json,
        f"oracle {difficulty}/{task}/{split}: accuracy {result['accuracy']:.3f} "
        f"over {episodes} episodes, mean {result['mean_steps']:.1f} steps (max {result['max_steps']})",
    )


@bench_app.command("env")
def bench_env(
    env_name: str = typer.Option("doom", "--env", help=_ENV_HELP),
    height: int = 168,
    width: int = 300,
    difficulty: str = typer.Option("easy", help=_DOOM_DIFFICULTY_HELP),
    interpolation: str = typer.Option("linear", help="linear | area | nearest"),
    steps: int = typer.Option(2000, min=100),
    as_json: bool = typer.Option(False, "--json"),
):
    """Raw ViZDoom vs our env (labels off/on), and the vector env with 1 and 2 workers."""
    from emml.bench import bench_env as run

    _own_engines(defer=False)
    _, cfg = _env_config(_gym_id(env_name), difficulty, height=height, width=width, interpolation=interpolation)
    result = run(cfg, steps=steps, vector_steps=steps)
    text = [f"{env_name} env bench at {width}x{height} (render {result['render']}):"]
    for key in ("labels_off", "labels_on"):
        r = result[key]
        text.append(
            f"  {key}: raw {r['raw_steps_per_s']:.0f} steps/s, ours {r['env_steps_per_s']:.0f} steps/s "
            f"(ratio {r['ratio']:.2f}); reset {r['env_reset_ms']:.2f} ms "
            f"vs new_episode {r['raw_new_episode_ms']:.2f} ms"
        )
    for w in (1, 2):
        text.append(f"  vector env, {w} worker(s): {result[f'vector_{w}_workers_steps_per_s']:.0f} steps/s")
    _echo(result, as_json, "\n".join(text))


@bench_app.command("train")
def bench_train_cmd(
    model: str = "dual_attention",
    aux: bool = typer.Option(True, "--aux/--no-aux"),
    profile: str = typer.Option("quick", help="Profile whose input size, actors and horizon are used."),
    updates: int = typer.Option(5, min=1),
    device: str = "cpu",
    runs: int = typer.Option(0, min=0, help="Also pack N end-to-end runs side by side: aggregate vs simulator limit."),
    sets: list[str] = typer.Option([], "--set", help="Override any config field."),
    part: str = typer.Option("both", help="both (model-only, end-to-end and their ratio), model or e2e."),
    stack: int = typer.Option(1, min=1, help="N seeds stacked in one model and process (vmap), vs one run."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Model-only (synthetic batches) vs end-to-end (real envs) training frames/s, in one run, with the time split;
    with --runs N, the aggregate of N packed runs against the raw simulator limit of the machine's cores."""
    from emml.bench import PARTS, bench_train
    from emml.profiles import profile_config
    from emml.rl.hardware import check_runnable

    try:
        cfg = profile_config(profile, "easy", _parse_sets(sets), model=model, aux=aux, device=device).validate()
        check_runnable(cfg)  # bench runs the model without a Trainer: the registry and the machine, before compute
    except ValueError as e:
        _fail(str(e))
    if part not in PARTS:
        _fail(f"--part {part!r}: allowed values are {', '.join(PARTS)}")
    _use_tcmalloc()
    _own_engines(defer=False)
    r = bench_train(cfg, updates, runs, part=part, stack=stack)
    if stack > 1:
        lines = [
            f"{model} at {r['width']}x{r['height']} on {r['device']}, {name}: one run {r[f'{key}_fps']:.0f} frames/s, "
            f"{stack} stacked runs {r[f'stacked_{key}_fps']:.0f} frames/s in all (×{r[f'stacked_{key}_gain']})"
            for key, name in (("model_only", "model-only"), ("end_to_end", "end to end"))
            if f"stacked_{key}_fps" in r
        ]
        _echo(r, as_json, "\n".join(lines))
        return
    if part != "both":
        fps = r.get("model_only_fps", r.get("end_to_end_fps"))
        _echo(r, as_json, f"{model} at {r['width']}x{r['height']} on {r['allocator']}: {part} {fps:.0f} frames/s")
        return
    split = ", ".join(f"{k} {100 * v:.0f}%" for k, v in r["time_split"].items())
    lines = [
        f"{model} at {r['width']}x{r['height']} on {r['device']} ({r['allocator']}), "
        f"{r['num_envs']}x{r['num_steps']} per update, "
        f"{r['env_groups']} env group(s): model-only {r['model_only_fps']:.0f} frames/s, end-to-end "
        f"{r['end_to_end_fps']:.0f} frames/s (ratio {r['ratio']:.2f}); end-to-end time: {split}"
    ]
    if "lockstep_fps" in r:
        gain = r["double_buffer_gain"]
        lines.append(f"lockstep (1 group): {r['lockstep_fps']:.0f} frames/s (double buffering ×{gain})")
    if "packed" in r:
        p = r["packed"]
        lines.append(
            f"{p['runs']} packed runs ({p['threads_per_run']} threads each): {p['aggregate_fps']:.0f} frames/s in all "
            f"{p['per_run_fps']}; raw simulator limit of {p['cores']} cores {p['simulator_limit_fps']:.0f} steps/s "
            f"(fraction {p['fraction_of_limit']:.2f})"
        )
    _echo(r, as_json, "\n".join(lines))


def _child_bench_args(profile: str, updates: int, sets: list[str], variants: list[dict] = ({},)) -> list[str]:
    """`bench train` options for child processes, after validating the config of every variant here: bad input
    fails before any child starts."""
    from emml.profiles import profile_config
    from emml.rl.hardware import check_runnable

    for extra in variants:
        try:
            check_runnable(profile_config(profile, "easy", {**_parse_sets(sets), **extra}).validate())
        except ValueError as e:
            _fail(str(e))
    return ["--profile", profile, "--updates", str(updates), *(a for s in sets for a in ("--set", s))]


@bench_app.command("alloc")
def bench_alloc_cmd(
    profile: str = typer.Option("quick", help="Profile whose input size, actors and horizon are used."),
    updates: int = typer.Option(2, min=1, help="Updates per measurement (after one warm-up update)."),
    rounds: int = typer.Option(3, min=1, help="Rounds; each runs every allocator once, interleaved."),
    sets: list[str] = typer.Option([], "--set", help="Override any config field."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Training frames/s (model-only and end-to-end) under each allocator this machine has, interleaved in one
    run: tcmalloc and mimalloc where installed, glibc tuned in-process (the default without them) and untuned."""
    from emml.bench import bench_alloc

    r = bench_alloc(_child_bench_args(profile, updates, sets), rounds)
    lines = [f"allocators, median of {rounds} interleaved rounds (frames/s; ratio to the best):"]
    for name, m in r["median_fps"].items():
        ratio = r["ratio_to_best"][name]
        lines.append(
            f"  {name:<12} model-only {m['model']:6.0f} ({ratio['model']:.2f})   "
            f"end-to-end {m['e2e']:6.0f} ({ratio['e2e']:.2f})"
        )
    _echo(r, as_json, "\n".join(lines))


@bench_app.command("workers")
def bench_workers_cmd(
    profile: str = typer.Option("quick", help="Profile whose input size, actors and horizon are used."),
    per_worker: list[int] = typer.Option([1, 4], "--per-worker", help="Envs per worker process to compare."),
    updates: int = typer.Option(2, min=1, help="Updates per measurement (after one warm-up update)."),
    rounds: int = typer.Option(3, min=1, help="Rounds; each runs every setting once, interleaved."),
    sets: list[str] = typer.Option([], "--set", help="Override any config field."),
    as_json: bool = typer.Option(False, "--json"),
):
    """End-to-end training frames/s with each number of envs per worker process, interleaved in one run."""
    from emml.bench import bench_workers

    r = bench_workers(
        _child_bench_args(profile, updates, sets, [{"envs_per_worker": k} for k in per_worker]), per_worker, rounds
    )
    lines = [f"envs per worker, median of {rounds} interleaved rounds (end-to-end frames/s; ratio to the best):"]
    for name, m in r["median_fps"].items():
        lines.append(f"  {name:<14} {m['e2e']:6.0f} ({r['ratio_to_best'][name]['e2e']:.2f})")
    _echo(r, as_json, "\n".join(lines))


@app.command()
def models(
    height: int = 168,
    width: int = 300,
    as_json: bool = typer.Option(False, "--json"),
):
    """The model registry with parameter counts at an input size (vocabulary of the Doom dataset)."""
    from emml.models import model_table
    from emml.tasks.language import Vocabulary, load_dataset

    vocab = Vocabulary.from_dataset(load_dataset("doom"))
    try:
        rows = model_table(len(vocab), height, width, 210)
    except ValueError as e:
        _fail(str(e))
    plugin = {r["name"]: f"  (plugin {r['source']})" if r["source"] != "emml" else "" for r in rows}
    _echo(
        rows,
        as_json,
        "\n".join(f"{r['name']:<18} {r['parameters']:>10,}  {r['description']}{plugin[r['name']]}" for r in rows),
    )


def _own_engines(defer: bool = True) -> None:
    """The ViZDoom engines this command starts end with it, on SIGINT/SIGTERM too
    (emml.envs.engine.install_signal_handlers). With `defer`, a command that plays or scores models but trains none
    yields the CPU to the trainings running beside it (emml.rl.contention.defer_to_learners), and says so."""
    from emml.envs.engine import install_signal_handlers
    from emml.rl.contention import defer_to_learners

    install_signal_handlers()
    if not defer:
        return
    message = defer_to_learners()
    if message:
        typer.echo(message, err=True)


def _use_tcmalloc() -> None:
    """Re-exec once under tcmalloc when installed, else tune glibc in-process (~2x CPU training speed either way,
    docs/throughput.md); EMML_MALLOC picks one (emml.alloc.CHOICES)."""
    from emml.alloc import reexec_under_tcmalloc

    try:
        reexec_under_tcmalloc()
    except ValueError as e:
        _fail(str(e))


def _parse_sets(sets: list[str]) -> dict:
    """'--set env.height=84 --set ppo.lr=1e-4' → {'env.height': 84, 'ppo.lr': 0.0001} (values parsed as TOML)."""
    import tomllib

    out = {}
    for item in sets:
        if "=" not in item:
            _fail(f"--set {item!r}: expected FIELD=VALUE, e.g. --set env.height=84")
        key, value = item.split("=", 1)
        try:
            out[key.strip()] = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError:
            out[key.strip()] = value
    return out


@app.command()
def train(
    model: str = typer.Option("dual_attention", help="Model registry name (emml models)."),
    difficulty: str = typer.Option("easy", help=_DIFFICULTY_HELP),
    aux: bool = typer.Option(False, "--aux/--no-aux", help="Train with the auxiliary task."),
    profile: str = typer.Option("quick", help="smoke | demo | quick | paper (reproduce/profiles.toml)"),
    seed: int = 0,
    table: str = typer.Option("adhoc", help="MLflow experiment / results table."),
    device: str = typer.Option("cpu", help="cpu | cuda"),
    frames: int = typer.Option(0, help="Override the profile's frames (0: keep)."),
    sets: list[str] = typer.Option([], "--set", help="Override any config field: --set env.shaping=false"),
    pack_seeds: str = typer.Option(
        "", help="Seeds to train packed in this process, e.g. 0,1,2: one stacked model (emml/rl/packed.py)."
    ),
    quiet: bool = False,
    as_json: bool = typer.Option(False, "--json"),
):
    """Train one run (resumes it if interrupted; a finished run is not retrained); with --pack-seeds, several
    seeds of it in one process, each written as its own run."""
    from emml.profiles import profile_config
    from emml.rl.hardware import check_runnable

    overrides = _parse_sets(sets)
    if frames:
        overrides["frames"] = frames
    try:
        seeds = [int(s) for s in pack_seeds.split(",")] if pack_seeds else [seed]
    except ValueError:
        _fail(f"--pack-seeds {pack_seeds!r}: allowed values are integers separated by commas, e.g. 0,1,2")
    try:
        cfgs = [
            profile_config(profile, difficulty, overrides, model=model, aux=aux, seed=s, table=table, device=device)
            for s in seeds
        ]
        cfg = check_runnable(cfgs[0].validate())  # the values, then the model registry and the machine (rl/hardware.py)
        if pack_seeds:
            from emml.rl.packed_trainer import check_packable

            check_packable(cfgs)
        from emml.preflight import check_train

        check_train(*cfgs)  # the store, the run and results folders, the results CSV: before any engine or run
    except ValueError as e:
        _fail(str(e))
    _use_tcmalloc()
    if cfg.num_updates * cfg.frames_per_update != cfg.frames and not (quiet or as_json):  # after the re-exec: once
        typer.echo(
            f"note: frames={cfg.frames:,} rounded up to whole updates of num_envs × num_steps = "
            f"{cfg.frames_per_update:,}: {cfg.num_updates * cfg.frames_per_update:,} frames",
            err=True,
        )
    _own_engines(defer=False)
    from emml.checkpoint import CheckpointError
    from emml.diskspace import NoSpaceError
    from emml.rl.trainer import train as run
    from emml.runlock import RunLocked
    from emml.runs import ConfigMismatch

    if pack_seeds:
        from emml.rl.packed_trainer import train_packed

        try:
            results = train_packed(cfgs, quiet=quiet or as_json)
        except (CheckpointError, ConfigMismatch, RunLocked, ValueError, NoSpaceError) as e:
            _fail(str(e))
        data = [{"run_dir": str(r.run_dir), "run_id": r.run_id, "frames": r.frames, **r.metrics} for r in results]
        text = [
            f"{run_name(c)} after {r.frames:,} frames: " + ", ".join(f"{k} {v:.3f}" for k, v in r.metrics.items())
            for c, r in zip(cfgs, results)
        ]
        _echo(data, as_json, "\n".join(text))
        return
    try:  # raised before any engine starts or anything is written, but a full disk (the run then ends FAILED)
        result = run(cfg, quiet=quiet or as_json)
    except (CheckpointError, ConfigMismatch, RunLocked, NoSpaceError) as e:
        _fail(str(e))
    data = {
        "run_dir": str(result.run_dir),
        "run_id": result.run_id,
        "frames": result.frames,
        "skipped": result.skipped,
        "resumed": result.resumed,
        **result.metrics,
    }
    _echo(
        data,
        as_json,
        ("already finished: " if result.skipped else "")
        + f"{run_name(cfg)} after {result.frames:,} frames: "
        + ", ".join(f"{k} {v:.3f}" for k, v in result.metrics.items())
        + f"\n  run dir {result.run_dir}",
    )


_CONTROLS = (
    "detectors (x_I := aux labels), target_mask (x_S := the referent's cells), type_gate (Eq. 4's gate from the "
    "dataset's word types), none (emml/config.py, ModelConfig.control)"
)


@app.command("eval")
def eval_checkpoint(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt"),
    episodes: int = typer.Option(100, min=1, help="Episodes per (task, split)."),
    seed: int = 10_000,
    control: str = typer.Option(None, help="Play under a diagnostic control instead of the run's: " + _CONTROLS),
    as_json: bool = typer.Option(False, "--json"),
):
    """Greedy accuracy of a checkpoint on SGN/EQA train/test (reproducible under --seed)."""
    from emml.runs import evaluate_checkpoint

    _check_checkpoint(checkpoint)
    _own_engines()
    if not as_json:
        typer.echo(f"evaluating {checkpoint}: {episodes} greedy episodes per task and split…", err=True)
    try:
        result = evaluate_checkpoint(checkpoint, episodes, seed, control=control)
    except ValueError as e:  # a control the model cannot take
        _fail(str(e))
    _echo(result, as_json, ", ".join(f"{k} {v:.3f}" for k, v in result.items()))


@app.command("rescore")
def rescore_runs(
    runs: list[Path] = typer.Argument(..., help="Finished run directories (or their checkpoint.pt)."),
    episodes: int = typer.Option(0, min=0, help="Episodes per (task, split); 0: the run's final_eval_episodes."),
    seed: int = typer.Option(10_000, help="First episode seed (the trainer's evaluations use 10,000)."),
    record: bool = typer.Option(True, "--record/--no-record", help="Also upsert the run's results-table row."),
    force: bool = typer.Option(False, "--force", help="Play again a run already scored with this protocol."),
    results_root: str = typer.Option(None, help="Results root of the rows (default: the run's, from its checkpoint)."),
    device: str = typer.Option("cpu", help="cpu | cuda"),
    as_json: bool = typer.Option(False, "--json"),
):
    """Re-score finished runs with the final-evaluation protocol (issue 33): results.json's metrics and the
    results-table row rewritten, training provenance kept, scored_sha / eval_episodes / eval_seed recorded."""
    from emml.checkpoint import load_checkpoint
    from emml.config import TrainConfig
    from emml.rescore import NoProvenance, NotFinished, check_finished, rescore, training_record
    from emml.runlock import RunLocked

    for run in runs:  # every run checked before any is played
        rdir = run if run.is_dir() else run.parent
        _check_checkpoint(rdir / "checkpoint.pt")
        ckpt = load_checkpoint(rdir / "checkpoint.pt")
        cfg = TrainConfig.from_dict(ckpt["config"])
        if results_root is not None:
            cfg.results_root = results_root
        try:
            check_finished(rdir, ckpt, cfg)
            training_record(rdir, ckpt, cfg)
        except (NotFinished, NoProvenance) as e:
            _fail(str(e))
    _own_engines()
    data, lines = [], []
    for run in runs:
        if not as_json:
            typer.echo(f"re-scoring {run}…", err=True)
        try:
            r = rescore(run, episodes, seed, record=record, force=force, results_root=results_root, device=device)
        except RunLocked as e:  # being trained: its score is not final
            _fail(str(e))
        data.append({"run_dir": str(r.run_dir), "before": r.before, "after": r.after, "played": r.played})
        data[-1]["csv"] = str(r.csv) if r.csv else None
        keys = [k for k in r.after if k not in ("eval_episodes", "eval_seed")]
        scores = ", ".join(f"{k} {_score(r.before.get(k))} -> {r.after[k]:.3f}" for k in keys)
        protocol = f"{r.before['eval_episodes']} -> {r.after['eval_episodes']} episodes, seed {r.after['eval_seed']}"
        lines.append(f"{r.run_dir.name}: {scores} ({protocol})" + ("" if r.played else " [already scored]"))
        lines.append(f"  wrote {r.run_dir / 'results.json'}" + (f" and its row in {r.csv}" if r.csv else ""))
    _echo(data, as_json, "\n".join(lines))


def _score(value) -> str:
    return "-" if value is None else f"{value:.3f}"


@app.command()
def transfer(
    checkpoint: Path = typer.Argument(
        ..., help="A checkpoint of an SGN Dual-Attention run that does not know the words"
    ),
    words: str = typer.Option("red,pillar", help="New words, comma-separated, in channel order."),
    episodes: int = typer.Option(100, min=1, help="Greedy episodes per test instruction."),
    detector: str = typer.Option("labels", help="Detector kind: labels (the engine's label buffer)."),
    seed: int = 10_000,
    as_json: bool = typer.Option(False, "--json"),
):
    """Table 4 on one checkpoint (§5.4): append detectors for new words, score every SGN test instruction that
    holds one, without fine-tuning; rows as in reproduce/table4.toml."""
    from emml.registry import load_table
    from emml.transfer import transfer_checkpoint

    _check_checkpoint(checkpoint)
    _own_engines()
    new_words = tuple(w.strip() for w in words.split(",") if w.strip())
    try:
        scores = transfer_checkpoint(checkpoint, new_words, episodes=episodes, seed=seed, detector=detector)
    except ValueError as e:
        _fail(str(e))
    table = load_table("table4")
    rows = {}
    if new_words == table.transfer.words:  # the paper's words: its rows (and ours below them)
        rows = {r.label: sum(scores[x] for x in r.instructions) / len(r.instructions) for r in table.rows}
    width = max(map(len, [*scores, *rows]))
    text = "\n".join(
        [f"{k:<{width}}  {v:.2f}" for k, v in rows.items()]
        + (["", "per instruction:"] if rows else [])
        + [f"{k:<{width}}  {v:.2f}" for k, v in scores.items()]
    )
    _echo({"instructions": scores, "rows": rows, "episodes": episodes, "words": list(new_words)}, as_json, text)


@app.command()
def diagnose(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt"),
    episodes: int = typer.Option(
        20, min=0, help="Sampled SGN episodes for the attention and detector figures (0: no SGN figures)."
    ),
    step0_episodes: int = typer.Option(100, min=0, help="Resets for the actor's sensitivity to the target slot."),
    eqa_episodes: int = typer.Option(10, min=0, help="Greedy episodes per EQA question (0: no EQA table)."),
    sgn_outcomes: int = typer.Option(
        0, min=0, help="Greedy SGN episodes per split, seeded as `emml eval`: how each ends, per instruction (0: none)."
    ),
    split: str = typer.Option("both", help="The SGN splits of --sgn-outcomes: train | test | both."),
    control: str = typer.Option(None, help="Play under a diagnostic control instead of the run's: " + _CONTROLS),
    seed: int = 20_000,
    as_json: bool = typer.Option(False, "--json"),
):
    """Why a model does (not) follow instructions: attention on the target, per-word detector AP, and how much
    the first move depends on where the target stands (emml/diagnose.py); per EQA question its accuracy, answers,
    where the attention sits and the GA2 gate per channel (emml/diagnose_eqa.py); per SGN instruction its success
    and how its episodes end: target, wrong object (which), time-out (emml/diagnose_sgn.py)."""
    from emml.diagnose import diagnose_checkpoint, summary_line
    from emml.diagnose_eqa import eqa_table
    from emml.diagnose_sgn import diagnose_sgn_checkpoint, sgn_table
    from emml.tasks.language import check_choice

    _check_checkpoint(checkpoint)
    _own_engines()
    try:
        check_choice("split", split, ("train", "test", "both"))
        result = diagnose_checkpoint(checkpoint, episodes, step0_episodes, seed, eqa_episodes, control)
        if sgn_outcomes:
            splits = ("train", "test") if split == "both" else (split,)
            result["sgn_outcomes"] = diagnose_sgn_checkpoint(checkpoint, sgn_outcomes, splits=splits, control=control)
    except ValueError as e:  # a control the model cannot take, a split that is not one
        _fail(str(e))
    lines = []
    if episodes:
        ap = sorted(result["detector_ap_words"].items(), key=lambda x: -x[1])
        slots = "; ".join(f"slot {s}: " + " ".join(f"{p:.2f}" for p in m) for s, m in result["step0_moves"].items())
        lines += [
            summary_line(result) + f" ({result['frames']} frames)",
            "detector AP per word: " + ", ".join(f"{w} {v:.2f}" for w, v in ap),
            _saturation_line(result),
            "step-0 move distribution (forward left right answer) by target slot: "
            + (slots or _no_step0(step0_episodes)),
        ]
    if result["conv3_one_way"] is not None:
        lines.append(
            f"conv3 since its init: {result['conv3_one_way']:.0%} of a channel's weights moved one way (median; 50%: "
            f"no common direction), weight sum moved {result['conv3_shift']:.2f} (median |sum|)"
        )
    if "eqa" in result:
        lines += ([""] if lines else []) + [eqa_table(result["eqa"])]
    if "sgn_outcomes" in result:
        lines += ([""] if lines else []) + [sgn_table(result["sgn_outcomes"])]
    _echo(result, as_json, "\n".join(lines))


def _saturation_line(result: dict) -> str:
    """x_I's saturation (emml.diagnose.x_image_saturation): how many channels are pinned, and which."""
    channels = result["x_image_channels"]
    pinned = [w for w, c in channels.items() if c["pinned"]]
    return (
        f"x_I saturation: {len(pinned)}/{len(channels)} channels pinned on every cell"
        + (f" ({', '.join(pinned)})" if pinned else "")
        + f"; spatial std of x_I {result['x_image_spatial_std']:.3f} (per channel: "
        + ", ".join(f"{w} {c['spatial_std']:.3f}" for w, c in channels.items())
        + ")"
    )


def _no_step0(step0_episodes: int) -> str:
    """Why the step-0 figures are missing: none asked for, or a difficulty whose spawn is not fixed (Hard)."""
    return "n/a (--step0-episodes 0)" if not step0_episodes else "n/a (the spawn is not fixed: Hard)"


@app.command("probe-eqa")
def probe_eqa_cmd(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt (Dual-Attention with its GA2 gate, on EQA)"),
    episodes: int = typer.Option(40, help="First frames per question (seeds 30,000+)."),
    readouts: str = typer.Option("last,mean", help="x_sent readouts to train, comma-separated: last | mean."),
    seeds: int = typer.Option(3, help="Encoders trained per readout (seeds 0, 1, ...)."),
    steps: int = typer.Option(600, help="Adam steps per encoder (minibatches of --batch frames)."),
    batch: int = typer.Option(128, help="Frames per minibatch."),
    lr: float = typer.Option(3e-3, help="Adam's learning rate."),
    eq1_words: str = typer.Option(
        "all", help="Words Eq. 1 sums the channels of: all (as the model) | content (function words left out)."
    ),
    init: str = typer.Option(
        "checkpoint", help="Where the retrained GRU and Linear start: checkpoint (its weights) | fresh (a new draw)."
    ),
    activation: str = typer.Option("relu", help="x_sent's activation on the retrained Linear: relu | softplus."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Would another question encoder answer the EQA test questions (issue 34)? On the first frames of EQA
    episodes, conv and Dual-Attention frozen, x_sent's encoder (GRU + Linear; the embedding copied from the
    checkpoint, frozen) retrained on the training questions' answers per readout and seed; answer accuracy on the
    train and test questions beside the checkpoint's own encoder (emml/probe_eqa.py)."""
    from emml.probe_eqa import ProbeOptions, probe_checkpoint, probe_table

    chosen = tuple(r.strip() for r in readouts.split(",") if r.strip())
    try:
        options = ProbeOptions(
            episodes, chosen, seeds, steps, batch, lr, eq1_words=eq1_words, init=init, activation=activation
        ).validate()
    except ValueError as e:
        _fail(str(e))
    _check_checkpoint(checkpoint)
    _own_engines()
    if not as_json:
        typer.echo(f"probing {checkpoint}: {episodes} first frames per EQA question…", err=True)
    try:
        result = probe_checkpoint(checkpoint, options)
    except ValueError as e:  # a model without a GA2 gate, a run not scored on EQA
        _fail(str(e))
    _echo(result, as_json, probe_table(result))


def _models(*paths: Path) -> list[tuple[str, object, object]]:
    """(label, model, config) per checkpoint, each checked first; the label says aux or no aux and the run."""
    from emml.runs import load_model

    out = []
    for path in paths:
        _check_checkpoint(path)
        model, cfg = load_model(path)
        out.append((f"{cfg.model} {'aux' if cfg.aux else 'no aux'} ({path.parent.name})", model, cfg))
    return out


@visualize_app.command("channels")
def visualize_channels(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt"),
    compare: Path | None = typer.Option(None, help="A second checkpoint (e.g. the No-Aux run) for another column."),
    out: Path = typer.Option(Path("reports"), help="Folder for the PNG."),
    seed: int = 0,
):
    """The channel figure: per word, its aux label, each model's conv3 channel, and the frame."""
    from emml.report.visualize import channels_figure

    models = _models(checkpoint, *([compare] if compare else []))
    _own_engines()
    out = _out(out)
    path = out / f"channels-{checkpoint.parent.name}.png"
    channels_figure([(label, m) for label, m, _ in models], models[0][2].env, path, seed=seed)
    typer.echo(f"wrote {path}")


@visualize_app.command("attention")
def visualize_attention(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt"),
    task: str = typer.Option("sgn", help="sgn | eqa"),
    out: Path = typer.Option(Path("reports"), help="Folder for the PNG."),
    seed: int = 0,
    rows: int = typer.Option(6, min=1, help="Steps shown, spread over the episode."),
):
    """The attention figure: one greedy episode, rows over time (frame, x_spat, x_Ans, action), x_sent on top."""
    from emml.report.visualize import attention_figure, record_episode
    from emml.tasks.language import check_choice

    try:
        check_choice("task", task, ("sgn", "eqa"))
    except ValueError as e:
        _fail(str(e))
    ((_, model, cfg),) = _models(checkpoint)
    _own_engines()
    out = _out(out)
    ep = record_episode(model, cfg.env, task, seed)
    path = out / f"attention-{task}-{checkpoint.parent.name}-s{seed}.png"
    attention_figure(ep, path, rows)
    typer.echo(f"wrote {path} ('{ep.sentence}': {'success' if ep.success else 'failure'} in {len(ep.frames)} steps)")


@visualize_app.command("house")
def visualize_house(
    out: Path = typer.Option(Path("reports"), help="Folder for the PNG."),
    seed: int = 0,
):
    """Three first-person views of the House with furniture in the episode's colours (Appendix C's example views)."""
    from emml.report.house_views import house_views

    _own_engines()
    path = house_views(_out(out) / "house-views.png", seed=seed)
    typer.echo(f"wrote {path}")


@app.command()
def video(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt"),
    episodes: int = typer.Option(3, min=1, help="Episodes per task (SGN, then EQA unless the run is SGN only)."),
    out: Path = typer.Option(Path("reports"), help="Folder for the GIFs."),
    seed: int = 0,
):
    """A captioned GIF per greedy episode: the sentence, each action, the outcome."""
    from emml.report.visualize import episode_gif, record_episode

    ((_, model, cfg),) = _models(checkpoint)
    _own_engines()
    out = _out(out)
    tasks = ("sgn", "eqa") if cfg.env.tasks == "both" else (cfg.env.tasks,)
    for task in tasks:
        for i in range(episodes):
            ep = record_episode(model, cfg.env, task, seed + i)
            path = episode_gif(ep, out / f"{checkpoint.parent.name}-{task}-s{seed + i}.gif")
            typer.echo(f"wrote {path} ('{ep.sentence}': {'success' if ep.success else 'failure'})")


@app.command()
def demo(
    out: Path = typer.Option(Path("reports"), help="Where the report goes."),
    profile: str = typer.Option("demo", help="Profile of the demo run."),
):
    """The main job: a short Dual-Attention training (aux on) on Doom Easy instruction following (SGN), evaluated,
    logged to MLflow, with a report (accuracies, training curve, diagnostics) in reports/."""
    from emml.profiles import profile_config

    # SGN only: within the demo's minutes the agent leaves chance on instructions (both tasks need more frames)
    over = {"env.tasks": "sgn"}
    try:
        cfg = profile_config(profile, "easy", over, model="dual_attention", aux=True, seed=0, table="demo").validate()
        from emml.preflight import check_train

        check_train(cfg)  # before any engine or MLflow run
    except ValueError as e:
        _fail(str(e))
    _use_tcmalloc()
    _own_engines(defer=False)
    from emml.report.demo import write_demo_report
    from emml.rl.trainer import train as run

    result = run(cfg)
    for path in write_demo_report(cfg, result, _out(out)):
        typer.echo(f"wrote {path}")


@app.command("list")
def list_experiments(
    profile: str = typer.Option("quick", help="smoke | demo | quick | paper: which results count as finished."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Every table in reproduce/ with its runs and how many are finished under the profile."""
    from emml.launch import run_states
    from emml.profiles import load_profiles
    from emml.registry import list_tables, load_table

    if profile not in load_profiles():
        _fail(f"profile={profile!r} is unknown; choose one of {', '.join(map(repr, load_profiles()))}")
    data, lines = [], []
    for name in list_tables():
        try:
            table = load_table(name)
            states = run_states(name, profile)
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


@app.command("run")
def run_table(
    table: str = typer.Argument(
        ...,
        help="table2 | table3 | table4 | table5 (reproduce/<table>.toml), experiments/<name> "
        "(reproduce/experiments/<name>.toml), or a table file of your own (x.toml)",
    ),
    profile: str = typer.Option("quick", help="smoke | demo | quick | paper (reproduce/profiles.toml)"),
    backend: str = typer.Option("local", help="local (process pool) | slurm (submitit)"),
    jobs: int = typer.Option(0, help="Concurrent local runs (0: half the cores; cuda: and what GPU memory holds)."),
    device: str = typer.Option("cpu", help="cpu | cuda"),
    partition: str = typer.Option(None, help="Slurm partition."),
    time_min: int = typer.Option(24 * 60, help="Slurm time limit per run, minutes."),
    gpus: int = typer.Option(0, help="GPUs per Slurm job."),
    cpus: int = typer.Option(8, help="CPUs per Slurm job."),
    wait: bool = typer.Option(False, help="Slurm: wait for the jobs to end."),
    only: list[str] = typer.Option(
        [], "--only", help="Only the runs whose FIELD=VALUE (row, model, difficulty, aux, seed), e.g. difficulty=easy."
    ),
    as_json: bool = typer.Option(False, "--json"),
):
    """Train every run of a table (skips finished runs, resumes interrupted ones); a placeholder table exits 0."""
    from dataclasses import asdict

    from emml.launch import run_table as launch
    from emml.registry import load_table

    selection = {}
    for item in only:
        key, sep, value = item.partition("=")
        if not sep:
            _fail(f"--only {item!r}: expected FIELD=VALUE, e.g. --only difficulty=easy")
        selection[key.strip()] = value.strip()
    try:
        loaded = load_table(table)  # a .toml path: its name is the file's stem (emml.registry.own_table)
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
            device=device,
            partition=partition,
            time_min=time_min,
            gpus=gpus,
            cpus=cpus,
            wait=wait,
            log=(lambda m: None) if as_json else typer.echo,
            only=selection,
        )
    except ValueError as e:
        _fail(str(e))
    data = asdict(report)
    if report.stopped:
        from emml.plugins import configured

        plugins = [arg for p in configured() for arg in ("--plugin", p)]  # a model of one's own needs its plugin
        only_args = [arg for o in only for arg in ("--only", o)]
        # quoted for the shell: a row label has spaces ("--only 'row=softplus, mean'")
        again = shlex.join(["emml", *plugins, "run", table, "--profile", profile, *only_args])
        _echo(data, as_json, _stopped_line(report, again))
        raise typer.Exit(130)
    _echo(
        data,
        as_json,
        f"{table} [{profile}]: {len(report.done)} trained, {len(report.skipped)} already finished, "
        f"{len(report.failed)} failed" + (f", {len(report.submitted)} jobs submitted" if report.submitted else ""),
    )
    if report.failed:
        raise typer.Exit(1)


def _stopped_line(report, again: str) -> str:
    """The one line a stopped launch ends with: what stopped, what was left, and the command that resumes it."""
    return (
        f"stopped by {report.stopped}: {len(report.done)} runs finished, {len(report.unfinished)} not (those in "
        f"progress ended KILLED, resumable from their checkpoints); resume with: {again}"
    )


@app.command()
def campaign(
    name: str = typer.Argument(..., help="A campaign of reproduce/campaigns/ (e.g. reference)."),
    show_status: bool = typer.Option(False, "--status", help="Show each run as done / running / interrupted / to do."),
    pin: bool = typer.Option(
        True,
        "--pin/--no-pin",
        help="Train from a git worktree of this commit (.campaign/<sha>), so edits cannot reach it.",
    ),
    jobs: int = typer.Option(0, help="Concurrent local runs (0: half the cores)."),
    device: str = typer.Option("cpu", help="cpu | cuda"),
    run_root: str = typer.Option(None, help="Run dirs (default: the checkout's runs/)."),
    results_root: str = typer.Option(None, help="Results CSVs (default: the checkout's results/)."),
    steps: list[str] = typer.Option(
        [], "--step", help="Only this step (by name, as --status shows it; repeatable); the campaign's order stays."
    ),
    as_json: bool = typer.Option(False, "--json"),
):
    """Train a campaign's unfinished runs in its order (resuming interrupted ones), or show its status."""
    import os
    import sys
    from dataclasses import asdict

    from emml.campaign import load_campaign, pin_worktree, run_campaign, select_steps, status
    from emml.tracking import project_path, project_root, tracking_uri

    step_args = [x for n in steps for x in ("--step", n)]
    try:
        plan = select_steps(load_campaign(name), steps)
    except ValueError as e:
        _fail(str(e))
    if show_status:
        rows = status(plan, run_root, results_root)
        _echo([asdict(r) for r in rows], as_json, _status_text(plan, rows, _runs_at_once(jobs, device), device))
        return
    if pin:  # re-exec from a worktree of HEAD, writing into this checkout's runs, results and MLflow store
        try:
            tree = pin_worktree(project_root(), log=typer.echo)
        except ValueError as e:
            _fail(str(e))
        roots = {
            "--run-root": str(project_path(run_root or "runs")),
            "--results-root": str(project_path(results_root or "results")),
        }
        args = [sys.executable, "-m", "emml.cli", "campaign", name, "--no-pin", "--jobs", str(jobs), "--device", device]
        args += [x for kv in roots.items() for x in kv] + step_args
        args += ["--json"] if as_json else []
        env = {**os.environ, "PYTHONPATH": str(tree), "MLFLOW_TRACKING_URI": tracking_uri()}
        typer.echo(f"{name}: training from {tree} (commit {tree.name})")
        os.chdir(tree)  # `python -m` puts the working directory first on sys.path: the tree's emml, not this one's
        os.execve(sys.executable, args, env)
    _use_tcmalloc()
    try:
        reports = run_campaign(plan, run_root, results_root, device=device, jobs=jobs or None, log=typer.echo)
    except ValueError as e:
        _fail(str(e))
    failed = {k: v for r in reports for k, v in r.failed.items()}
    if reports and reports[-1].stopped:
        again = shlex.join(["emml", "campaign", name, *step_args])
        _echo([asdict(r) for r in reports], as_json, _stopped_line(reports[-1], again))
        raise typer.Exit(130)
    _echo(
        [asdict(r) for r in reports],
        as_json,
        f"{name}: {sum(len(r.done) for r in reports)} trained, {sum(len(r.skipped) for r in reports)} already "
        f"finished, {len(failed)} failed",
    )
    if failed:
        raise typer.Exit(1)


def _runs_at_once(jobs: int, device: str) -> int:
    """`jobs`, or when 0 what a launch on `device` would take (emml.launch.default_jobs); a device that is not one,
    or (for the default) that this machine lacks, fails by name."""
    from emml.config import check_device_name
    from emml.launch import default_jobs
    from emml.rl.hardware import check_device

    try:
        check_device_name(device)
        if not jobs:
            check_device(device)
    except ValueError as e:
        _fail(f"{e} (or give --jobs N to estimate for N runs at a time)")
    return jobs or default_jobs(device)


def _status_text(plan, rows, at_once: int = 1, device: str = "cpu") -> str:
    """--status as text: one line per run, by step, and the estimated time left with `at_once` runs side by side."""
    from emml.campaign import NODE_RUNS, wall_seconds

    def hours(seconds: float | None) -> str:
        return "?" if seconds is None else f"{seconds / 3600:.1f} h"

    lines = [f"{plan.name}: {plan.title}"]
    width = max((len(r.run_name) for r in rows), default=0)
    for step in plan.steps:
        mine = [r for r in rows if r.step == step.name]
        done = sum(r.state == "done" for r in mine)
        cost = ""
        if done < len(mine):
            here = sum(r.seconds_left or 0.0 for r in mine if r.state != "done")
            node = wall_seconds(mine, NODE_RUNS, node=True)
            cost = f"; ~{hours(here)} here, ~{node / 60:.0f} min of a GPU node ({NODE_RUNS} at a time, training)"
        lines.append(f"{step.name} ({step.table} [{step.profile}]): {done}/{len(mine)} done{cost}")
        lines.append(f"  decides: {', '.join(step.claims)}" if step.claims else "  decides: no claim (an experiment)")
        for r in mine:
            who = f" pid {r.holder.get('pid')} on {r.holder.get('host')}" if r.holder else ""
            left = "" if r.state == "done" else f", ~{hours(r.seconds_left)} left"
            lines.append(f"  {r.state:<11} {r.run_name:<{width}} {r.frames:>10,}/{r.target:,} frames{left}{who}")
    todo = [r.seconds_left for r in rows if r.state != "done"]
    unknown = sum(s is None for s in todo)
    total = sum(s for s in todo if s is not None)
    measured = "training frames/s and evaluation seconds measured from this machine's runs of each profile"
    if at_once == 1:
        left = f"~{hours(total)} on this machine (one at a time; {measured})"
    else:  # each step a launch of `at_once` slots; a step of one run holds the machine alone (emml.campaign)
        left = (
            f"~{hours(total)} of run time, ~{hours(wall_seconds(rows, at_once))} on this machine with {at_once} "
            f"runs at a time on {device}, step by step (--jobs; {measured}, under the packing they trained at)"
        )
    lines.append(
        f"left: {len(todo)} runs, {left}"
        + (f"; {unknown} runs of a profile not yet measured here are not counted" if unknown else "")
    )
    return "\n".join(lines)


@app.command()
def report(
    table: str = typer.Argument(..., help="table2 | table3 | table4 | table5, or a table file of your own (x.toml)"),
    profile: str = typer.Option("quick", help="smoke | demo | quick | paper"),
    curves: bool = typer.Option(True, "--curves/--no-curves", help="Also plot training curves (needs MLflow)."),
    out: Path = typer.Option(None, help="Output folder (default: reports/)."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Ours beside the paper: reports/TABLE-PROFILE.md/.tex (mean (each seed) | paper, the runs' deviations from the
    paper, an rliable aggregate) and -curves.png/.pdf (smoke: under scratch/reports)."""
    from emml.profiles import load_profiles
    from emml.report.tables import report_table

    if profile not in load_profiles():
        _fail(f"profile={profile!r} is unknown; choose one of {', '.join(map(repr, load_profiles()))}")
    if curves:  # they read MLflow
        _check_store()
    try:
        if table.endswith(".toml"):  # a table of one's own: reported by its name, the file's stem
            from emml.registry import own_table

            table = own_table(table)
        data = report_table(table, profile, out=_out(out) if out else None)
    except ValueError as e:
        _fail(str(e))
    data["notes"] = []
    if curves:
        from emml.report.curves import plot_table

        paths, notes = plot_table(table, profile, out=_out(out) if out else None)
        data["paths"] += [str(p) for p in paths]
        data["notes"] = notes
    text = "\n".join([data["caption"], *[f"note: {n}" for n in data["notes"]], *[f"wrote {p}" for p in data["paths"]]])
    _echo(data, as_json, text)


@app.command("reports")
def reports(out: Path = typer.Option(None, help="Output folder (default: reports/).")):
    """Every table, curve and figure for the profiles that have results, and reports/index.md linking them."""
    from emml.report.index import write_reports

    _check_store()  # the curves read MLflow
    _own_engines()
    typer.echo(f"wrote {write_reports(_out(out) if out else None, log=typer.echo)}")


@app.command("backfill-config")
def backfill_config(
    paths: list[Path] = typer.Argument(..., help="Run dirs, or folders holding them (e.g. runs/table2)."),
):
    """Copy each finished run's config from its checkpoint into its results.json (runs finished before the trainer
    wrote it there), so reports read the deviations from the paper without loading checkpoints. A run still
    training is skipped."""
    from emml.report.saved_config import backfill_config as backfill
    from emml.report.saved_config import run_dirs
    from emml.tracking import project_path

    found = run_dirs([project_path(p) for p in paths])
    if not found:
        _fail(f"no run dir (a folder with checkpoint.pt) at or under {', '.join(map(str, paths))}")
    for run_dir in found:
        typer.echo(f"{run_dir}: {backfill(run_dir)}")


@app.command("import-runs")
def import_runs_cmd(
    paths: list[Path] = typer.Argument(None, help="Run dirs, or folders holding them (default: runs/)."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Import finished run dirs (results.json, metrics.csv) into the MLflow store, one FINISHED run each in its
    table's experiment with the trainer's tags, its config as params and its whole curve, so that `make ui` shows
    the committed runs. Once: a run already in the store (trained or imported here) is skipped, and so is an
    unfinished one (its trainer logs it)."""
    from emml.import_runs import import_runs
    from emml.tracking import project_path, tracking_uri

    roots = [project_path(p) for p in paths] if paths else [project_path("runs")]
    missing = [str(p) for p in roots if paths and not p.exists()]
    if missing:
        _fail(f"no such run dir or folder: {', '.join(missing)}")
    _check_store()
    results = import_runs(roots, log=None if as_json else lambda r: typer.echo(r.line()))
    counts = {k: sum(r.outcome == k for r in results) for k in ("imported", "skipped", "failed")}
    text = ", ".join(f"{n} {k}" for k, n in counts.items()) + f" (MLflow store {tracking_uri()})"
    _echo({"uri": tracking_uri(), **counts, "runs": [vars(r) for r in results]}, as_json, text)
    if counts["failed"]:
        _fail(f"{counts['failed']} run dirs not imported: their errors are above")


if __name__ == "__main__":
    app()
