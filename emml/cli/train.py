"""Training and scoring: `emml train`, `eval`, `rescore`, `transfer` and `demo`."""

from __future__ import annotations

from pathlib import Path

import typer

from emml.cli.common import (
    _CONTROLS,
    _DIFFICULTY_HELP,
    _check_checkpoint,
    _echo,
    _fail,
    _out,
    _own_engines,
    _parse_sets,
    _use_tcmalloc,
)
from emml.runs.rundir import run_name


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
    from emml.config.profiles import profile_config
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
        from emml.runs.preflight import check_train

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
    from emml.rl.trainer import train as run
    from emml.runs.checkpoint import CheckpointError
    from emml.runs.diskspace import NoSpaceError
    from emml.runs.records import RecordError
    from emml.runs.rundir import ConfigMismatch, RunDirError
    from emml.runs.runlock import RunLocked

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
    except (CheckpointError, ConfigMismatch, RunLocked, NoSpaceError, RunDirError, RecordError) as e:
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


def eval_checkpoint(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt"),
    episodes: int = typer.Option(100, min=1, help="Episodes per (task, split)."),
    seed: int = 10_000,
    control: str = typer.Option(None, help="Play under a diagnostic control instead of the run's: " + _CONTROLS),
    as_json: bool = typer.Option(False, "--json"),
):
    """Greedy accuracy of a checkpoint on SGN/EQA train/test (reproducible under --seed)."""
    from emml.eval.evaluate import evaluate_checkpoint

    _check_checkpoint(checkpoint)
    _own_engines()
    if not as_json:
        typer.echo(f"evaluating {checkpoint}: {episodes} greedy episodes per task and split…", err=True)
    try:
        result = evaluate_checkpoint(checkpoint, episodes, seed, control=control)
    except ValueError as e:  # a control the model cannot take
        _fail(str(e))
    _echo(result, as_json, ", ".join(f"{k} {v:.3f}" for k, v in result.items()))


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
    from emml.config.schema import TrainConfig
    from emml.eval.rescore import NoProvenance, NotFinished, check_finished, rescore, training_record
    from emml.runs.checkpoint import load_checkpoint
    from emml.runs.runlock import RunLocked

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
    from emml.eval.transfer import transfer_checkpoint
    from emml.experiments.tables import load_table

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


def demo(
    out: Path = typer.Option(Path("reports"), help="Where the report goes."),
    profile: str = typer.Option("demo", help="Profile of the demo run."),
):
    """The main job: a short Dual-Attention training (aux on) on Doom Easy instruction following (SGN), evaluated,
    logged to MLflow, with a report (accuracies, training curve, diagnostics) in reports/."""
    from emml.config.profiles import profile_config

    # SGN only: within the demo's minutes the agent leaves chance on instructions (both tasks need more frames)
    over = {"env.tasks": "sgn"}
    try:
        cfg = profile_config(profile, "easy", over, model="dual_attention", aux=True, seed=0, table="demo").validate()
        from emml.runs.preflight import check_train

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
