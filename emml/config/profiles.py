"""Profiles (reproduce/profiles.toml): the same protocol at different cost — smoke, demo, quick, paper."""

from __future__ import annotations

import copy
import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path

import tomllib

from emml.config.env_kinds import ENV_KINDS
from emml.config.paths import REPRODUCE_DIR
from emml.config.schema import TrainConfig, apply_overrides, match_env_class

PROFILES_FILE = REPRODUCE_DIR / "profiles.toml"
PROFILES_ENV = "EMML_PROFILES"
"""Environment variable naming another profiles file (a researcher's own profiles; the tests' shorter smoke): the
processes a command starts (one per run) read the same file."""


def profiles_file() -> Path:
    """The profiles file in force: $EMML_PROFILES when set, else reproduce/profiles.toml."""
    return Path(os.environ.get(PROFILES_ENV) or PROFILES_FILE)


class ProfileError(ValueError):
    """reproduce/profiles.toml cannot be read or holds a value that is not a TrainConfig field of its type."""


def load_profiles(path: Path | None = None) -> dict[str, dict]:
    """Every profile of the file, each checked against TrainConfig (names and types) before anything uses it."""
    path = Path(path or profiles_file())
    try:
        stamp = path.stat().st_mtime_ns
    except OSError:
        stamp = None
    if stamp is not None and _LOADED.get(path, (None,))[0] == stamp:  # every run's name reads its profile
        return copy.deepcopy(_LOADED[path][1])
    profiles = _load_profiles(path)
    if stamp is not None:
        _LOADED[path] = (stamp, copy.deepcopy(profiles))
    return profiles


_LOADED: dict[Path, tuple[int, dict]] = {}
"""Profiles files read and checked, by path: (modification time, profiles)."""


def _load_profiles(path: Path) -> dict[str, dict]:
    try:
        with open(path, "rb") as f:
            profiles = tomllib.load(f)
    except OSError as e:
        raise ProfileError(f"{path}: cannot be read ({e.strerror})") from None
    except tomllib.TOMLDecodeError as e:
        raise ProfileError(f"{path}: not valid TOML ({e})") from None
    for name, values in profiles.items():
        where = f"{path} [{name}]"
        if not isinstance(values, dict):
            raise ProfileError(f"{where}: a profile is a table of TrainConfig fields, found {values!r}")
        seeds = values.get("seeds", [0])
        if not isinstance(seeds, list) or not seeds or not all(type(s) is int for s in seeds):
            raise ProfileError(f"{where}: 'seeds' must be a non-empty list of integers, found {seeds!r}")
        frames_hard = values.get("frames_hard", 1)
        if type(frames_hard) is not int:
            raise ProfileError(f"{where}: 'frames_hard' must be an integer, found {frames_hard!r}")
        fields_only = {k: v for k, v in values.items() if k not in ("seeds", "frames_hard")}
        try:
            apply_overrides(TrainConfig(profile=name), fields_only, source=where)
        except ValueError as e:
            raise ProfileError(str(e)) from None
    return profiles


@dataclass(frozen=True)
class Profile:
    """One profile of the profiles file, read and checked: resolved once where a command starts (`resolve_profile`)
    and passed down as this value, so that every run's config and name read the same values without rereading the
    file (a launch's workers and Slurm jobs get it pickled)."""

    name: str
    """The profile's name (its table in the profiles file; `TrainConfig.profile` of every run it makes)."""
    values: dict = field(compare=False)
    """Its TrainConfig fields by dotted name, as the file gives them (less `seeds` and `frames_hard`)."""
    seeds: tuple[int, ...] = (0,)
    """The seeds every setting of a table is trained with."""
    frames_hard: int | None = None
    """`frames` of a run whose env kind counts its frames as Hard's (§5.1: 50M in Hard; Appendix C: the House);
    None: the profile's `frames`."""
    source: str = ""
    """Where it was read ('<file> [<name>]'), for the errors that name a bad value."""

    def config(self, difficulty: str = "easy", overrides: dict | None = None, **fields) -> TrainConfig:
        """The TrainConfig of one run: the profile's values (its frames chosen by difficulty), then dotted
        ``overrides``; ``fields`` (e.g. run_root) are TrainConfig fields that win over the profile's."""
        values = {k: v for k, v in self.values.items() if k not in fields}  # the caller's fields win
        kind = ENV_KINDS.get(difficulty)  # an unknown difficulty fails in validate(), naming it
        if kind is not None and kind.frames_key == "frames_hard" and self.frames_hard is not None:
            values["frames"] = self.frames_hard
        cfg = TrainConfig(profile=self.name, **fields)
        cfg.env = match_env_class(dataclasses.replace(cfg.env, difficulty=difficulty))
        apply_overrides(cfg, values, source=self.source)
        apply_overrides(cfg, overrides or {})
        return cfg

    @property
    def scratch(self) -> bool:
        """Whether its numbers are not results: its results_root is under scratch/, not results/."""
        return Path(self.values.get("results_root", "results")).parts[:1] == (SCRATCH,)


def resolve_profile(profile: str | Profile) -> Profile:
    """The profile named ``profile`` (a `Profile` is returned as it is): ValueError naming the profiles there are
    when the file has none of that name."""
    if isinstance(profile, Profile):
        return profile
    profiles = load_profiles()
    if profile not in profiles:
        raise ValueError(f"profile={profile!r} is unknown; choose one of {', '.join(map(repr, profiles))}")
    values = dict(profiles[profile])
    seeds = tuple(values.pop("seeds", [0]))
    frames_hard = values.pop("frames_hard", None)
    return Profile(profile, values, seeds, frames_hard, f"{profiles_file()} [{profile}]")


def profile_config(
    profile: str | Profile, difficulty: str = "easy", overrides: dict | None = None, **fields
) -> TrainConfig:
    """A TrainConfig for ``profile`` (its frames chosen by difficulty), then dotted ``overrides``; ``fields`` (e.g.
    run_root) are TrainConfig fields that win over the profile's (`Profile.config`)."""
    return resolve_profile(profile).config(difficulty, overrides, **fields)


def profile_seeds(profile: str | Profile) -> list[int]:
    return list(resolve_profile(profile).seeds)


COMMITTED = ("results", "reports")
"""The committed folders of results CSVs and reports (relative to the checkout)."""
SCRATCH = "scratch"
"""Gitignored folder for what a profile whose numbers are not results writes (smoke, 512 frames): its run_root and
results_root point under it in reproduce/profiles.toml, and its reports go to scratch/reports."""


def is_scratch(profile: str | Profile) -> bool:
    """Whether the profile's numbers are not results: its results_root is under scratch/, not results/."""
    return resolve_profile(profile).scratch


def refuse_committed(profile: str | Profile, path: str | Path, what: str) -> None:
    """ValueError when ``path`` (a results CSV or report being written) lies in the checkout's committed results/
    or reports/ and ``profile`` is a scratch profile: 512-frame smoke numbers are not results."""
    from emml.config.paths import project_path

    if not isinstance(profile, Profile) and profile not in load_profiles():
        return
    profile = resolve_profile(profile)
    if not profile.scratch:
        return
    path = project_path(path).resolve()
    for folder in COMMITTED:
        if path.is_relative_to(project_path(folder).resolve()):
            raise ValueError(
                f"{what} {path}: the '{profile.name}' profile's numbers are not results and are not written under the "
                f"committed {folder}/; they go under {SCRATCH}/ (its default), or name another folder"
            )
