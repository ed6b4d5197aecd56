"""What every command group shares: one-line failures, output as text or JSON, output folders, the checks before a
command runs (checkpoint, MLflow store), the engines a command owns, the allocator, --set."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from emml.config.env_kinds import DOOM_ID, ENV_KINDS, GYM_ENVS, kinds_of


def _fail(message: str) -> None:
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    raise typer.Exit(2)


def _check_checkpoint(path: Path) -> None:
    """Fail with one line naming the path unless it holds an emml checkpoint (before any engine starts)."""
    from emml.runs.checkpoint import CheckpointError, load_checkpoint

    try:
        load_checkpoint(path)
    except CheckpointError as e:
        _fail(str(e))


def _check_store() -> None:
    """Fail with one line naming the MLflow store unless it answers and takes writes within seconds
    (emml/runs/preflight.py): MLflow itself retries an unreachable store for ~100 s, then prints a traceback."""
    from emml.runs.preflight import check_store

    try:
        check_store()
    except ValueError as e:
        _fail(str(e))


def _out(path: Path) -> Path:
    """An output folder, made; relative paths resolve under the checkout like runs/ and results/ (README)."""
    from emml.config.paths import project_path

    path = project_path(path)
    path.mkdir(parents=True, exist_ok=True)
    return path


def _echo(data, as_json: bool, text: str) -> None:
    typer.echo(json.dumps(data, indent=2) if as_json else text)


_ENV_HELP = " | ".join(e.name for e in GYM_ENVS.values()) + " (house: the House domain, Appendix C)"


_DOOM_DIFFICULTY_HELP = " | ".join(kinds_of(DOOM_ID)) + " (doom only)"


_DIFFICULTY_HELP = " | ".join(ENV_KINDS) + " (house: the House domain, Appendix C)"


def _gym_id(env_name: str) -> str:
    """The gym id of an ``--env`` name (emml/config/env_kinds.py), or fail naming the allowed names."""
    ids = {e.name: e.gym_id for e in GYM_ENVS.values()}
    if env_name not in ids:
        _fail(f"--env={env_name!r} is not allowed; choose one of {', '.join(map(repr, ids))}")
    return ids[env_name]


def _env_config(gym_id: str, difficulty: str, **fields):
    """(difficulty, validated config) of the env ``gym_id``: an env that plays one kind (the House) plays it
    whatever ``difficulty`` says; a bad value fails with the field's name."""
    from emml.config.schema import ENV_CONFIGS

    kinds = kinds_of(gym_id)
    if len(kinds) == 1:
        difficulty = kinds[0]
    try:
        return difficulty, ENV_CONFIGS[gym_id](difficulty=difficulty, **fields).validate()
    except ValueError as e:
        _fail(str(e))


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
    docs/throughput.md); EMML_MALLOC picks one (emml.rl.alloc.CHOICES)."""
    from emml.rl.alloc import reexec_under_tcmalloc

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


_CONTROLS = (
    "detectors (x_I := aux labels), target_mask (x_S := the referent's cells), type_gate (Eq. 4's gate from the "
    "dataset's word types), none (emml/config/schema.py, ModelConfig.control)"
)


def _models(*paths: Path) -> list[tuple[str, object, object]]:
    """(label, model, config) per checkpoint, each checked first; the label says aux or no aux and the run."""
    from emml.runs.rundir import load_model

    out = []
    for path in paths:
        _check_checkpoint(path)
        model, cfg = load_model(path)
        out.append((f"{cfg.model} {'aux' if cfg.aux else 'no aux'} ({path.parent.name})", model, cfg))
    return out
