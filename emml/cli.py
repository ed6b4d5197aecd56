"""`emml …`: one typer app. Thin: parses arguments, calls the library, prints (or `--json`)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

app = typer.Typer(add_completion=False, no_args_is_help=True, help=__doc__)
tasks_app = typer.Typer(no_args_is_help=True, help="The datasets: instructions and questions with their splits.")
bench_app = typer.Typer(no_args_is_help=True, help="Throughput benchmarks (ratios measured in one run).")
app.add_typer(tasks_app, name="tasks")
app.add_typer(bench_app, name="bench")


def _fail(message: str) -> None:
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    raise typer.Exit(2)


def _echo(data, as_json: bool, text: str) -> None:
    typer.echo(json.dumps(data, indent=2) if as_json else text)


@tasks_app.command("show")
def tasks_show(dataset: str = typer.Argument("doom", help="doom (house: not built yet)"), as_json: bool = typer.Option(False, "--json")):
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


@app.command()
def oracle(
    difficulty: str = typer.Option("easy", help="easy | hard"),
    task: str = typer.Option("sgn", help="sgn | eqa | both"),
    split: str = typer.Option("train", help="train | test"),
    episodes: int = typer.Option(100, min=1),
    seed: int = 0,
    height: int = 168,
    width: int = 300,
    as_json: bool = typer.Option(False, "--json"),
):
    """Accuracy of the scripted expert (privileged state): every episode must be solvable."""
    from emml.agents.oracle import run_oracle
    from emml.config import DoomConfig
    from emml.envs.doom import DoomEnv
    from emml.envs.engine import install_signal_handlers

    install_signal_handlers()
    try:
        cfg = DoomConfig(difficulty=difficulty, tasks=task, split=split, height=height, width=width).validate()
    except ValueError as e:
        _fail(str(e))
    env = DoomEnv(cfg)
    try:
        result = run_oracle(env, episodes, seed)
    finally:
        env.close()
    result = {"difficulty": difficulty, "task": task, "split": split, **result}
    _echo(result, as_json, f"oracle {difficulty}/{task}/{split}: accuracy {result['accuracy']:.3f} "
          f"over {episodes} episodes, mean {result['mean_steps']:.1f} steps (max {result['max_steps']})")


@bench_app.command("env")
def bench_env(
    height: int = 168,
    width: int = 300,
    difficulty: str = "easy",
    steps: int = typer.Option(2000, min=100),
    as_json: bool = typer.Option(False, "--json"),
):
    """Raw ViZDoom vs our env (labels off/on), and the vector env with 1 and 2 workers."""
    from emml.bench import bench_env as run
    from emml.config import DoomConfig
    from emml.envs.engine import install_signal_handlers

    install_signal_handlers()
    try:
        cfg = DoomConfig(height=height, width=width, difficulty=difficulty).validate()
    except ValueError as e:
        _fail(str(e))
    result = run(cfg, steps=steps, vector_steps=steps)
    text = [f"env bench at {width}x{height} (render {result['render']}):"]
    for key in ("labels_off", "labels_on"):
        r = result[key]
        text.append(
            f"  {key}: raw {r['raw_steps_per_s']:.0f} steps/s, ours {r['env_steps_per_s']:.0f} steps/s "
            f"(ratio {r['ratio']:.2f}); reset {r['env_reset_ms']:.2f} ms vs new_episode {r['raw_new_episode_ms']:.2f} ms"
        )
    for w in (1, 2):
        text.append(f"  vector env, {w} worker(s): {result[f'vector_{w}_workers_steps_per_s']:.0f} steps/s")
    _echo(result, as_json, "\n".join(text))


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
    _echo(rows, as_json, "\n".join(f"{r['name']:<18} {r['parameters']:>10,}  {r.get('description', '')}" for r in rows))


@app.command()
def demo(
    out: Path = typer.Option(Path("reports"), help="Where the report goes."),
    episodes: int = typer.Option(3, min=1, help="Episodes per (difficulty, task)."),
):
    """The main job: the scripted expert on a few Easy and Hard episodes, recorded as a GIF with a summary."""
    from emml.demo import oracle_demo
    from emml.envs.engine import install_signal_handlers

    install_signal_handlers()
    paths = oracle_demo(out, episodes)
    for p in paths:
        typer.echo(f"wrote {p}")


if __name__ == "__main__":
    app()
