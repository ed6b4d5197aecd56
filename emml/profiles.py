"""Profiles (reproduce/profiles.toml): the same protocol at different cost — smoke, demo, quick, paper."""

from __future__ import annotations

from pathlib import Path

import tomllib

from emml.config import TrainConfig, apply_overrides

PROFILES_FILE = Path(__file__).resolve().parent.parent / "reproduce" / "profiles.toml"


def load_profiles(path: Path = PROFILES_FILE) -> dict[str, dict]:
    with open(path, "rb") as f:
        return tomllib.load(f)


def profile_config(profile: str, difficulty: str = "easy", overrides: dict | None = None, **fields) -> TrainConfig:
    """A TrainConfig for ``profile`` (its frames chosen by difficulty), then ``fields`` and dotted ``overrides``."""
    profiles = load_profiles()
    if profile not in profiles:
        raise ValueError(f"profile={profile!r} is unknown; choose one of {', '.join(map(repr, profiles))}")
    values = dict(profiles[profile])
    values.pop("seeds", None)
    hard_frames = values.pop("frames_hard", values.get("frames"))
    if difficulty == "hard":
        values["frames"] = hard_frames
    cfg = TrainConfig(profile=profile, **fields)
    cfg.env.difficulty = difficulty
    apply_overrides(cfg, values)
    apply_overrides(cfg, overrides or {})
    return cfg


def profile_seeds(profile: str) -> list[int]:
    return list(load_profiles()[profile].get("seeds", [0]))
