"""The datasets, the models, the oracle and the benchmarks: `emml tasks show`, `models`, `oracle` and
`emml bench ...`."""

from __future__ import annotations

from pathlib import Path

import typer

from emml.cli.common import (
    JSON_HELP,
    SET_HELP,
    BenchPart,
    DoomDifficulty,
    EnvName,
    Interpolation,
    Split,
    Tasks,
    _echo,
    _env_config,
    _fail,
    _gym_id,
    _out,
    _own_engines,
    _parse_sets,
    _use_tcmalloc,
    device_option,
    model_option,
    profile_option,
)
from emml.config.env_kinds import DOOM_ID

_ENV_HELP = "The environment: the Doom room, or the House of Appendix C."
_DIFFICULTY_HELP = "Doom's difficulty (the House has one)."
_HEIGHT_HELP = "Observation height in pixels."
_WIDTH_HELP = "Observation width in pixels."


def tasks_show(
    dataset: str = typer.Argument("doom", help="doom (Table 7) | house (Table 8)."),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """A dataset's instructions and questions by task and split, its vocabulary and objects."""
    from emml.tasks.language import SPLITS, TASKS, Vocabulary, load_dataset

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
    for kind in TASKS:
        for split in SPLITS:
            sents = ds.select(kind, split)
            data[f"{kind}_{split}"] = [s.text for s in sents]
            lines.append(f"{kind.upper()} {split} ({len(sents)}):")
            lines += [f"  {s.text}" for s in sents]
    _echo(data, as_json, "\n".join(lines))


def oracle(
    env_name: EnvName = typer.Option("doom", "--env", help=_ENV_HELP),
    difficulty: DoomDifficulty = typer.Option("easy", help=_DIFFICULTY_HELP),
    task: Tasks = typer.Option("sgn", help="The episodes' task (both: 50/50)."),
    split: Split = typer.Option("train", help="The instructions' and questions' split."),
    episodes: int = typer.Option(100, min=1, help="Episodes to play."),
    seed: int = typer.Option(0, help="Seed of the first episode (episode i plays seed + i)."),
    height: int = typer.Option(168, help=_HEIGHT_HELP),
    width: int = typer.Option(300, help=_WIDTH_HELP),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
    video: Path = typer.Option(None, help="Also record a few Easy and Hard episodes as a GIF in this folder."),
):
    """Accuracy of a scripted expert that sees the true state: proof every episode is solvable."""
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


def models(
    height: int = typer.Option(168, help=_HEIGHT_HELP),
    width: int = typer.Option(300, help=_WIDTH_HELP),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """The model registry with parameter counts at an input size.

    The vocabulary is the Doom dataset's; each model's x_S formula as the code computes it."""
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


def bench_env(
    env_name: EnvName = typer.Option("doom", "--env", help=_ENV_HELP),
    height: int = typer.Option(168, help=_HEIGHT_HELP),
    width: int = typer.Option(300, help=_WIDTH_HELP),
    difficulty: DoomDifficulty = typer.Option("easy", help=_DIFFICULTY_HELP),
    interpolation: Interpolation = typer.Option("linear", help="Resize filter from the render to the observation."),
    steps: int = typer.Option(2000, min=100, help="Steps per measurement."),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Raw ViZDoom vs our env (labels off/on), and the vector env with 1 and 2 workers."""
    from emml.rl.bench import bench_env as run

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


def bench_train_cmd(
    model: str = model_option(help="The model to measure (`emml models` lists them)."),
    aux: bool = typer.Option(True, "--aux/--no-aux", help="With the auxiliary task."),
    profile: str = profile_option(help="Profile whose input size, actors and horizon are used."),
    updates: int = typer.Option(5, min=1, help="Updates per measurement."),
    device: str = device_option(),
    runs: int = typer.Option(0, min=0, help="Also pack N end-to-end runs side by side: aggregate vs simulator limit."),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    part: BenchPart = typer.Option("both", help="both: model-only, end-to-end and their ratio; or one of them."),
    stack: int = typer.Option(1, min=1, help="N seeds stacked in one model and process (vmap), vs one run."),
    graphs: bool = typer.Option(False, "--graphs", help="One run plain, then as CUDA graphs (--runs N: captured)."),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Training frames/s, model-only against end to end, in one run.

    Model-only trains on synthetic batches, end to end on real envs; with the time split. With --runs N, the
    aggregate of N packed runs against the raw simulator limit of the machine's cores."""
    from emml.config.profiles import profile_config
    from emml.rl.bench import PARTS, bench_train
    from emml.rl.prepare import prepare

    try:
        cfg = profile_config(profile, "easy", _parse_sets(sets), model=model, aux=aux, device=device)
        (cfg,) = prepare(cfg, writes=False)  # bench runs the model without a Trainer: the registry and the machine
    except ValueError as e:
        _fail(str(e))
    if part not in PARTS:
        _fail(f"--part {part!r}: allowed values are {', '.join(PARTS)}")
    _use_tcmalloc()
    _own_engines(defer=False)
    r = bench_train(cfg, updates, runs, part=part, stack=stack, graphs=graphs)
    if graphs:
        lines = [
            f"{model} at {r['width']}x{r['height']} on {r['device']}, {key.replace('_', ' ')}: plain "
            f"{g['plain_fps']:.0f} frames/s, CUDA graphs {g['graphs_fps']:.0f} (×{g['gain']})"
            for key, g in r["graphs"].items()
        ]
        if "packed" in r:
            p = r["packed"]
            lines.append(
                f"{p['runs']} runs packed, captured: {p['aggregate_fps']:.0f} frames/s in all, "
                f"{100 * p['fraction_of_limit']:.0f}% of the simulator limit ({p['simulator_limit_fps']:.0f})"
            )
        _echo(r, as_json, "\n".join(lines))
        return
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
    from emml.config.profiles import profile_config
    from emml.rl.prepare import prepare

    for extra in variants:
        try:
            prepare(profile_config(profile, "easy", {**_parse_sets(sets), **extra}), writes=False)
        except ValueError as e:
            _fail(str(e))
    return ["--profile", profile, "--updates", str(updates), *(a for s in sets for a in ("--set", s))]


def bench_alloc_cmd(
    profile: str = profile_option(help="Profile whose input size, actors and horizon are used."),
    updates: int = typer.Option(2, min=1, help="Updates per measurement (after one warm-up update)."),
    rounds: int = typer.Option(3, min=1, help="Rounds; each runs every allocator once, interleaved."),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Training frames/s under each memory allocator this machine has.

    Model-only and end to end, interleaved in one run: tcmalloc and mimalloc where installed, glibc tuned
    in-process (the default without them) and untuned."""
    from emml.rl.bench import bench_alloc

    r = bench_alloc(_child_bench_args(profile, updates, sets), rounds)
    lines = [f"allocators, median of {rounds} interleaved rounds (frames/s; ratio to the best):"]
    for name, m in r["median_fps"].items():
        ratio = r["ratio_to_best"][name]
        lines.append(
            f"  {name:<12} model-only {m['model']:6.0f} ({ratio['model']:.2f})   "
            f"end-to-end {m['e2e']:6.0f} ({ratio['e2e']:.2f})"
        )
    _echo(r, as_json, "\n".join(lines))


def bench_workers_cmd(
    profile: str = profile_option(help="Profile whose input size, actors and horizon are used."),
    per_worker: list[int] = typer.Option([1, 4], "--per-worker", help="Envs per worker process to compare."),
    updates: int = typer.Option(2, min=1, help="Updates per measurement (after one warm-up update)."),
    rounds: int = typer.Option(3, min=1, help="Rounds; each runs every setting once, interleaved."),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """End-to-end training frames/s with each number of envs per worker process, interleaved in one run."""
    from emml.rl.bench import bench_workers

    r = bench_workers(
        _child_bench_args(profile, updates, sets, [{"envs_per_worker": k} for k in per_worker]), per_worker, rounds
    )
    lines = [f"envs per worker, median of {rounds} interleaved rounds (end-to-end frames/s; ratio to the best):"]
    for name, m in r["median_fps"].items():
        lines.append(f"  {name:<14} {m['e2e']:6.0f} ({r['ratio_to_best'][name]['e2e']:.2f})")
    _echo(r, as_json, "\n".join(lines))
