"""What every command group shares: one-line failures, output as text or JSON, output folders, the checks before a
command runs (checkpoint, MLflow store), the engines a command owns, the allocator, --set."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Literal

import typer

from emml.config.env import INTERPOLATIONS
from emml.config.env_kinds import DOOM_ID, ENV_KINDS, GYM_ENVS, kinds_of
from emml.config.schema import ACTIVATIONS, CONTROLS, DEVICES, EQ1_WORDS, SPLITS, TASK_CHOICES, TASKS

# --- the choices of the options: metavar, validation before anything runs, shell completion -------------------------
# Literal types, built from the data that declares each set (typer shows them as <a|b>, refuses another value naming
# the allowed ones, completes them); the command receives a plain str, so configs and checkpoints never hold a
# member of a CLI enum.
Difficulty = Literal[tuple(ENV_KINDS)]
"""Where a run trains: easy | hard | house (emml/config/env_kinds.py)."""
DoomDifficulty = Literal[kinds_of(DOOM_ID)]
"""The Doom room's difficulties: easy | hard."""
EnvName = Literal[tuple(e.name for e in GYM_ENVS.values())]
"""The environments by their command-line name: doom | house."""
Tasks = Literal[TASK_CHOICES]
"""What a run plays: both | sgn | eqa (`DoomConfig.tasks`)."""
Task = Literal[TASKS]
Split = Literal[SPLITS]
SPLITS_OR_BOTH = (*SPLITS, "both")
"""A command that reads one split or both (train | test | both)."""
Splits = Literal[SPLITS_OR_BOTH]
Control = Literal[CONTROLS]
Eq1Words = Literal[EQ1_WORDS]
Activation = Literal[ACTIVATIONS]
Backend = Literal["local", "slurm"]
SlurmCluster = Literal["slurm", "local", "debug"]
Interpolation = Literal[INTERPOLATIONS]
BenchPart = Literal["both", "model", "e2e"]


def _choice(
    values: Callable[[], Sequence[str]],
    accept: Callable[[str], bool] | None = None,
    hint: Callable[[], str] | None = None,
):
    """(parser, completion) of an option whose allowed values are read when it is parsed, not when the command line
    is built (the profiles file, a plugin's models): a bad value is refused naming the allowed ones, then the closest
    (`did_you_mean`) and ``hint()`` when given."""

    def parse(value: str) -> str:
        allowed = tuple(values())
        if value in allowed or (accept is not None and accept(value)):
            return value
        message = f"{value!r} is not one of {', '.join(map(repr, allowed))}{did_you_mean(value, allowed)}"
        raise typer.BadParameter(message + (f" ({hint()})" if hint else ""))

    return parse, _names(values)


def did_you_mean(value: str, allowed: Sequence[str]) -> str:
    """'; did you mean 'quick'?' naming the allowed values closest to a misspelled one (difflib), or '' if none is
    close."""
    import difflib

    close = difflib.get_close_matches(value, list(allowed), n=3)
    return f"; did you mean {' or '.join(map(repr, close))}?" if close else ""


def _names(values: Callable[[], Sequence[str]]) -> Callable[[str], list[str]]:
    """A shell completion: the names ``values()`` reads when the shell asks, those that start with what is typed."""
    return lambda incomplete: [v for v in values() if v.startswith(incomplete)]


def _profile_names() -> tuple[str, ...]:
    from emml.config.profiles import load_profiles

    return tuple(load_profiles())


def _profile_metavar() -> str:
    """<smoke|demo|quick|paper>, read from the profiles file for the help only (a broken file is named, in one line,
    by every command before it runs)."""
    import tomllib

    from emml.config.profiles import profiles_file

    try:
        return "<" + "|".join(tomllib.loads(profiles_file().read_text())) + ">"
    except (OSError, ValueError):
        return "PROFILE"


def profile_option(default: str = "quick", help: str = "Protocol and cost (reproduce/profiles.toml).") -> typer.Option:
    """``--profile``: one of the profiles file's."""
    parse, complete = _choice(_profile_names)
    return typer.Option(default, parser=parse, autocompletion=complete, metavar=_profile_metavar(), help=help)


def device_option(help: str = "Where the model runs.") -> typer.Option:
    """``--device``: cpu or cuda (a GPU by index: cuda:1)."""
    parse, complete = _choice(lambda: DEVICES, accept=lambda v: v.startswith("cuda:") and v[5:].isdigit())
    return typer.Option("cpu", parser=parse, autocompletion=complete, metavar="<cpu|cuda|cuda:N>", help=help)


def _model_names() -> list[str]:
    from emml.models.registry import MODELS

    return list(MODELS)


def _plugin_hint() -> str:
    from emml.models.registry import PLUGIN_HINT

    return PLUGIN_HINT


def model_option(
    default: str = "dual_attention", help: str = "The model to train (`emml models` lists them)."
) -> typer.Option:
    """``--model``: one of the model registry's names (a loaded plugin's included: `emml --plugin` loads them before
    the command's options are parsed), completed from it; a misspelled name is refused before any compute naming the
    closest, the allowed ones, and how a plugin's model becomes known."""
    parse, complete = _choice(_model_names, hint=_plugin_hint)
    return typer.Option(default, parser=parse, autocompletion=complete, metavar="MODEL", help=help)


def _table_names() -> list[str]:
    from emml.experiments.table_files import table_names

    return table_names()


def table_argument(help: str) -> typer.Argument:
    """A table's name: completed from the table files of reproduce/ (table2..5, experiments/<name>); any other
    value is left to the command (a .toml file of one's own)."""
    return typer.Argument(..., autocompletion=_names(_table_names), metavar="TABLE", help=help)


def _campaign_names() -> list[str]:
    from emml.experiments.campaign.file import list_campaigns

    return list_campaigns()


def campaign_argument() -> typer.Argument:
    """A campaign's name: one of reproduce/campaigns/*.toml, completed from there (an unknown one is refused by
    `load_campaign`, naming those there are)."""
    help = "A campaign of reproduce/campaigns/ (e.g. reference)."
    return typer.Argument(..., autocompletion=_names(_campaign_names), metavar="NAME", help=help)


RUN_ROOT_HELP = "Folder of the run dirs (default: the checkout's runs/; same as --set run_root=DIR)."
RESULTS_ROOT_HELP = "Folder of the results CSVs (default: the checkout's results/; same as --set results_root=DIR)."
SEED_HELP = "Seed of the first episode (episode i plays seed + i)."
JSON_HELP = "Print the result as JSON on stdout."
QUIET_HELP = "Print only the result: no log lines, no progress bar."
SET_HELP = "Override a config field, FIELD=VALUE in TOML (a bare word is a string): --set env.tasks=sgn (repeatable)."


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
    """'--set env.height=84 --set ppo.lr=1e-4 --set env.tasks=sgn' → {'env.height': 84, 'ppo.lr': 0.0001,
    'env.tasks': 'sgn'}: each value parsed as TOML (numbers, booleans, quoted strings, lists, inline tables), a
    value that is not TOML taken as the string it spells (so 'sgn' and '"sgn"' are the same). A list or table that
    does not parse is refused, naming the TOML error: taken as a string, it would fail later and less clearly."""
    import tomllib

    out = {}
    for item in sets:
        if "=" not in item:
            _fail(f"--set {item!r}: expected FIELD=VALUE, e.g. --set env.height=84")
        key, value = item.split("=", 1)
        try:
            out[key.strip()] = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError as e:
            if value.strip()[:1] in ("[", "{"):
                _fail(f"--set {item!r}: {value.strip()!r} is not a TOML list or table ({e})")
            out[key.strip()] = value.strip()
    return out


_CONTROLS = (
    "detectors: x_I := the aux labels; target_mask: x_S := the referent's cells; type_gate: Eq. 4's gate from "
    "the dataset's word types; none: the model's own"
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
