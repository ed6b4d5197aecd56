"""Env kinds: where a run trains — Doom Easy, Doom Hard (§4 'Environments', §5.1) or the House (Appendix C).

Each kind is declared once, here; every list of difficulties, table label, paper budget and config class derives
from `ENV_KINDS` (config/schema.py and profiles.py, experiments/tables.py and fidelity.py, report/). Pure data with no
import from the package, so the config layer reads it: the config class of a kind is the one declaring its gym id
(`GYM_ID`, emml/config/schema.py), and its env class the one that id is registered with (emml/__init__.py,
emml/envs/vector.py).
"""

from __future__ import annotations

from dataclasses import dataclass

DOOM_ID = "emml/Doom-v0"
"""The one-room ViZDoom tasks, Easy and Hard (emml/envs/doom.py)."""
HOUSE_ID = "emml/House-v0"
"""The House domain (emml/envs/house.py)."""


@dataclass(frozen=True)
class GymEnv:
    """A Gymnasium environment of the package."""

    gym_id: str
    """Its Gymnasium id (`gym.make`)."""
    entry_point: str
    """'module:Class' of its env class, imported only when an env is made (emml/envs sits above this layer)."""
    name: str
    """How the command line names it (``--env``)."""
    max_episode_steps: int
    """Its registered spec's episode limit (`gym.make` wraps it in TimeLimit): its config's default `max_steps`,
    where the env truncates too (§5.1: 210; Appendix C: 420)."""


GYM_ENVS = {
    e.gym_id: e
    for e in (
        GymEnv(DOOM_ID, "emml.envs.doom:DoomEnv", "doom", 210),
        GymEnv(HOUSE_ID, "emml.envs.house:HouseEnv", "house", 420),
    )
}
"""The environments `import emml` registers, by gym id."""


@dataclass(frozen=True)
class EnvKind:
    """One place a run trains: an `env.difficulty` value and what the paper fixes for it."""

    name: str
    """The `env.difficulty` value (run names, a table's `columns.difficulties`)."""
    label: str
    """How tables, figures and captions write it."""
    gym_id: str
    """The environment that plays it (a key of `GYM_ENVS`)."""
    paper_frames: int
    """Training frames in the paper (§5.1: 10M in Easy, 50M in Hard; Appendix C: 50M in the House)."""
    paper_max_steps: int
    """Episode limit in agent steps in the paper (§5.1: 210; Appendix C: 420)."""
    frames_key: str
    """The profile key (reproduce/profiles.toml) giving its frames: 'frames' (Easy's budget, scaled) or
    'frames_hard' (the 50M budget, scaled)."""
    fixed_spawn: bool
    """The agent starts at one pose every episode (Easy, §4; the House, Appendix C): first frames are comparable
    across episodes (emml/eval/diagnose.py)."""
    source: str
    """Where the paper gives its training protocol, as fidelity captions cite it."""


ENV_KINDS = {
    k.name: k
    for k in (
        EnvKind("easy", "Easy", DOOM_ID, 10_000_000, 210, "frames", fixed_spawn=True, source="§5.1"),
        EnvKind("hard", "Hard", DOOM_ID, 50_000_000, 210, "frames_hard", fixed_spawn=False, source="§5.1"),
        EnvKind("house", "House", HOUSE_ID, 50_000_000, 420, "frames_hard", fixed_spawn=True, source="App. C"),
    )
}
"""Every env kind, by `env.difficulty` value, in the order tables list them."""


def kinds_of(gym_id: str) -> tuple[str, ...]:
    """The names of the kinds ``gym_id`` plays (the `difficulty` values its config allows)."""
    return tuple(k.name for k in ENV_KINDS.values() if k.gym_id == gym_id)


def env_label(difficulty: str) -> str:
    """The label of a kind; an unknown value as it is (an old results row keeps its cell)."""
    kind = ENV_KINDS.get(difficulty)
    return kind.label if kind is not None else str(difficulty)
