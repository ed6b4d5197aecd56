"""A campaign file (reproduce/campaigns/<name>.toml): held to its format (emml/experiments/file_formats.py: keys,
types, choices), then checked against the tables, profiles, claims and runs it names, before any compute; and each
step's runs in training order. What the steps are is the package's docstring (emml/experiments/campaign/__init__.py)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from emml.config.paths import REPRODUCE_DIR
from emml.config.toml_files import check_file, read_toml
from emml.experiments.file_formats import OWN_KEYS as OWN_KEYS  # what a step may not set (also imported from here)
from emml.experiments.file_formats import CampaignFile, StepEntry
from emml.experiments.plan import PlannedRun

CAMPAIGNS_DIR = REPRODUCE_DIR / "campaigns"
STEP_KEYS = tuple(StepEntry.model_fields)
"""The keys of a step (its format: emml/experiments/file_formats.py, `StepEntry`)."""
TOP_KEYS = tuple(CampaignFile.model_fields)
"""The keys of a campaign file (`CampaignFile`)."""


@dataclass(frozen=True)
class Step:
    """One step of a campaign: some runs of one table under one profile."""

    name: str
    """Short label (shown by --status)."""
    table: str
    """Table name (reproduce/<table>.toml), or ``experiments/<name>`` (reproduce/experiments/<name>.toml)."""
    profile: str
    """Profile (reproduce/profiles.toml)."""
    only: dict = field(default_factory=dict)
    """RunSpec field → value or list of values (emml.experiments.plan.select_runs); lists order the runs."""
    frames: int | None = None
    """Frames to train each run to, instead of the profile's (None: the profile's)."""
    note: str = ""
    """Why the step is there (free text)."""
    claims: tuple[str, ...] = ()
    """The claims its runs decide (ids of reproduce/claims.toml, emml/experiments/claims/); none for a step that
    measures something of ours (an experiment of an issue)."""
    settings: dict = field(default_factory=dict)
    """The step's `set`: TrainConfig.RUNTIME field → value for its runs, over the profile's (how a run is measured
    and run, e.g. eval_every; never what it is: its name and results row stay the table's)."""

    def overrides(self) -> dict:
        """The dotted TrainConfig overrides the step adds to its runs' own (emml.experiments.plan.with_overrides)."""
        return {**self.settings, **({"frames": self.frames} if self.frames is not None else {})}


@dataclass(frozen=True)
class Campaign:
    name: str
    path: Path
    title: str
    steps: tuple[Step, ...]


def select_steps(campaign: Campaign, names: list[str]) -> Campaign:
    """The campaign cut to the steps named (in the campaign's order, not the names'); no names: all of it. An
    unknown name fails naming the campaign's steps. E.g. a lent GPU node trains the steps a CPU is not at."""
    known = [s.name for s in campaign.steps]
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(
            f"step={unknown[0]!r} is not a step of campaign {campaign.name!r}; allowed: {', '.join(known)}"
        )
    if not names:
        return campaign
    return replace(campaign, steps=tuple(s for s in campaign.steps if s.name in names))


def list_campaigns(directory: Path = CAMPAIGNS_DIR) -> list[str]:
    return sorted(p.stem for p in directory.glob("*.toml"))


def load_campaign(name: str, directory: Path = CAMPAIGNS_DIR) -> Campaign:
    """Parse reproduce/campaigns/<name>.toml; every error names the file and the key, before any compute."""
    from emml.config.profiles import load_profiles
    from emml.experiments.claims import load_claims
    from emml.experiments.plan import ONLY_FIELDS, select_runs
    from emml.experiments.table_files import table_names

    path = directory / f"{name}.toml"
    if not path.is_file():
        known = ", ".join(list_campaigns(directory)) or "none"
        raise ValueError(f"campaign {name!r} not found ({path}); known campaigns: {known}")
    data = read_toml(path)
    check_file(path, data, CampaignFile)
    raw_steps = data["steps"]
    steps, profiles = [], load_profiles()
    tables = table_names()
    known_claims = load_claims()
    names: dict[str, int] = {}
    for i, raw in enumerate(raw_steps):
        where = f"steps[{i}]"
        if raw["name"] in names:  # --step and --status name steps: two of one name would be merged silently
            raise ValueError(
                f"{path}: {where}.name={raw['name']!r} is already the name of steps[{names[raw['name']]}]; step names "
                "must be unique"
            )
        names[raw["name"]] = i
        if raw["table"] not in tables:
            raise ValueError(f"{path}: {where}.table={raw['table']!r} is unknown; allowed: {', '.join(tables)}")
        if raw["profile"] not in profiles:
            raise ValueError(f"{path}: {where}.profile={raw['profile']!r} is unknown; allowed: {', '.join(profiles)}")
        only = raw.get("only", {})
        if any(k not in ONLY_FIELDS for k in only):
            raise ValueError(f"{path}: {where}.only must be a table of fields among {', '.join(ONLY_FIELDS)}")
        frames = raw.get("frames")
        step = Step(
            raw["name"],
            raw["table"],
            raw["profile"],
            only,
            frames,
            raw.get("note", ""),
            _claims(path, where, raw, known_claims),
            _settings(path, where, raw),
        )
        try:  # the selection names runs the table has (the values present are named otherwise)
            selected = select_runs(_declared(step.table, step.profile), step.only)
        except ValueError as e:
            raise ValueError(f"{path}: {where}.only: {e}") from None
        _check_runs(path, where, step, selected)
        steps.append(step)
    return Campaign(name, path, str(data.get("title", name)), tuple(steps))


def _check_runs(path: Path, where: str, step: Step, selected: dict) -> None:
    """Each run of the step as it would train, validated before anything starts (its frames at least one update,
    `TrainConfig.validate`): a bad step otherwise fails when the campaign reaches it, hours in."""
    from emml.experiments.plan import with_overrides

    for spec, _ in selected.values():
        try:
            with_overrides(spec, step.overrides()).to_config(step.profile).validate()
        except ValueError as e:
            raise ValueError(f"{path}: {where} ({spec.run_name(step.profile)}): {e}") from None


def _claims(path: Path, where: str, raw: dict, known: dict) -> tuple[str, ...]:
    """The step's `claim`: one id of reproduce/claims.toml or a list of them (the format checks which it is)."""
    value = raw.get("claim", [])
    ids = [value] if isinstance(value, str) else value
    for i in ids:
        if i not in known:
            raise ValueError(
                f"{path}: {where}.claim={i!r} is not a claim of reproduce/claims.toml; allowed: {', '.join(known)}"
            )
    return tuple(ids)


def _settings(path: Path, where: str, raw: dict) -> dict:
    """A step's `set` (its keys checked by the format: how a run is measured, `file_formats.SETTABLE`), each value of
    its field's type and range, before any compute."""
    from emml.config.schema import TrainConfig, apply_overrides

    settings = raw.get("set", {})
    try:
        apply_overrides(TrainConfig(), dict(settings), source=f"{where}.set").validate()
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    return dict(settings)


def _declared(table: str, profile: str) -> dict:
    """Run name → (RunSpec, None) for the table's runs under the profile: what a selection is checked against,
    without reading any run dir."""
    from emml.config.profiles import profile_seeds
    from emml.experiments.tables import load_table

    return {spec.run_name(profile): (spec, None) for spec in load_table(table).runs(profile_seeds(profile), profile)}


def step_runs(
    step: Step, runs: list[PlannedRun] | None = None, run_root: str | None = None, results_root: str | None = None
) -> list[PlannedRun]:
    """The step's runs in training order, planned (emml/experiments/plan.py) with the step's overrides on top of
    their own, as its launch trains them. ``runs``: its table's runs under its profile when already planned (several
    steps of one table and profile read the run dirs once); else planned here under ``run_root``/``results_root``."""
    from emml.experiments.plan import chosen, plan_runs, root_fields

    if runs is None:
        from emml.config.profiles import resolve_profile

        runs = plan_runs(step.table, resolve_profile(step.profile), root_fields(run_root, results_root))
    return chosen(runs, step.only, step.overrides())
