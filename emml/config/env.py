"""The environment configs: Doom (`emml/Doom-v0`, paper §4, §5.1, Appendix B) and the House (`emml/House-v0`,
Appendix C), and which config class a difficulty needs. Every field has a docstring with its unit and source."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import ClassVar, Literal

from emml.config.checks import Positive, Sentences, Words, check, check_choice
from emml.config.env_kinds import DOOM_ID, ENV_KINDS, HOUSE_ID, kinds_of

RESOLUTIONS_16_9 = ((256, 144), (320, 180), (400, 225), (512, 288), (640, 360), (800, 450), (1024, 576))
"""ViZDoom's 16:9 screen resolutions (width, height), the aspect of the paper's 300×168 input."""

TASKS = ("sgn", "eqa")
"""The tasks by id (0 SGN, 1 EQA) and as a sentence's ``kind``, metrics and log lines name them: the one list
(`DoomConfig.tasks` plays both, or one of them)."""
TASK_CHOICES = ("both", *TASKS)
"""Values of `DoomConfig.tasks`: both tasks (50/50 per episode), or one of `TASKS` (the single-task ablation)."""
SPLITS = ("train", "test")
"""The dataset splits (Table 7, Table 8): the instructions and questions a run trains on, and those held out. The
one list: `DoomConfig.split`, the datasets (emml/tasks), the evaluation's settings and the metrics read it."""
INTERPOLATIONS = ("area", "linear", "nearest")
"""Values of `DoomConfig.interpolation`: the resize filters from render to observation size."""
LABEL_GRIDS = ("receptive_field", "even")
"""Values of `DoomConfig.label_grid`: how label pixels meet the conv3 grid."""

VOCABULARY_SOURCES = ("all", "train_instructions")
"""Names a run's `DoomConfig.vocabulary` may give instead of a word list (`Vocabulary.from_dataset`, emml/tasks)."""


@dataclass
class DoomConfig:
    """The Doom environment `emml/Doom-v0` (paper §4 'Environments', §5.1, Appendix B)."""

    difficulty: str = "easy"
    """'easy': agent fixed, objects at 5 fixed slots in view; 'hard': random agent pose and object positions."""
    split: Literal[SPLITS] = "train"
    """'train' or 'test' instructions/questions (Table 7)."""
    tasks: Literal[TASK_CHOICES] = "both"
    """'both' (SGN and EQA, 50/50 per episode), 'sgn' or 'eqa' (single-task ablation, Table 3): `played`."""
    height: int = 168
    """Observation height in pixels (Appendix A: 3×168×300)."""
    width: int = 300
    """Observation width in pixels (Appendix A)."""
    aux_labels: bool = False
    """Add the V×h×w auxiliary detection labels ('aux') to the observation (§3.2 'Auxiliary Task'); with them
    ``info['target_mask']`` gives the h×w cells showing the episode's referent (privileged: no model reads it)."""
    target_in_obs: bool = False
    """With `aux_labels`, put the referent's cells in the observation too ('target'): for the 'target_mask'
    diagnostic control, the one model that reads them (the trainer and the evaluations turn it on for it)."""
    max_steps: Positive = 210
    """Episode limit in agent steps (§5.1: 'maximum length of 210 time steps')."""
    frame_skip: Positive = 5
    """Engine tics per agent step (paper silent; the reference SGN environment repeats each action 5 tics)."""
    turn_degrees: float = 15.0
    """Turn per left/right step, in degrees (paper silent; our choice: 3°/tic × 5 tics, 24 steps a full turn)."""
    reach_distance: float = 40.0
    """An object is reached within this 2-D distance of its centre, map units (reference SGN environment)."""
    success_reward: float = 1.0
    """Reaching the right object (SGN) or answering correctly (EQA) (§5.1)."""
    step_reward: float = -0.001
    """Every step (§5.1)."""
    wrong_reward: float = 0.0
    """Reaching a wrong object or answering wrongly. §5.1 names only +1 and -0.001 per step, so 0; the SGN
    environment the paper adapts used -0.2, under which a PPO agent can settle on never touching an object
    (measured in docs/fidelity.md)."""
    shaping: bool = True
    """Distance-based reward shaping in SGN (§5.1; off for the 'w/o reward shaping' ablation, Table 3)."""
    shaping_coef: float = 0.001
    """Shaping reward per map unit of decrease in distance to the target (paper silent: 'small'; ~0.1 per Easy
    episode)."""
    render: str = "auto"
    """ViZDoom render resolution 'WxH' (16:9); 'auto' takes the smallest one at least the observation size."""
    interpolation: Literal[INTERPOLATIONS] = "linear"
    """Resize filter from render to observation size: 'linear' (our choice: 5× faster than 'area', the reference
    env's cv2.INTER_AREA, and alike at the 0.94 scale of 320×180 → 300×168), 'area' or 'nearest'."""
    label_grid: Literal[LABEL_GRIDS] = "receptive_field"
    """How label pixels meet the conv3 grid (paper silent): 'receptive_field', the cell whose receptive field is
    centred nearest (emml/config/geometry.py), or 'even', an even partition of the frame (off by up to one cell at
    the right and bottom edges, since conv3 has no padding)."""
    max_words: Positive = 10
    """Token sequence length (padded with 0)."""
    vocabulary: Words | Literal[VOCABULARY_SOURCES] | None = None
    """The run's vocabulary (channel order); None builds the default, every word of the dataset; a name builds
    one from the dataset: 'all' (the default) or 'train_instructions' (the training instructions' words only:
    the transfer experiment, Table 4). The trainer pins it to the word list, saved with the run."""
    aux_words: Words | None = None
    """Words that get aux labels; None: every word but the superlatives (§3.2; function words get all-zero
    labels). The transfer experiment passes the training words only."""
    instructions: Sentences | None = None
    """Restrict episodes to these sentences (must be in the chosen split); None: all of the split."""
    dataset: str = "doom"
    """Which tasks/<name>.toml."""

    GYM_ID: ClassVar[str] = DOOM_ID
    """The environment this class configures (not a field); it plays the kinds of env_kinds.py with this id."""
    DIFFICULTIES: ClassVar[tuple[str, ...]] = kinds_of(DOOM_ID)
    """The allowed `difficulty` values (not a field): Easy and Hard (§4)."""

    @property
    def played(self) -> tuple[str, ...]:
        """The tasks the env draws episodes of, in `TASKS` order: both for 'both', else the one named."""
        return TASKS if self.tasks == "both" else (self.tasks,)

    def validate(self) -> DoomConfig:
        check_choice("difficulty", self.difficulty, self.DIFFICULTIES)
        from emml.config.geometry import conv_output_size

        conv_output_size(self.height, self.width)  # raises naming height/width when too small
        check(self)
        if self.target_in_obs and not self.aux_labels:
            raise ValueError("target_in_obs=True needs aux_labels=True: the referent's cells come from the labels")
        if self.render != "auto":
            allowed = [f"{w}x{h}" for w, h in RESOLUTIONS_16_9]
            check_choice("render", self.render, ["auto", *allowed])
        if self.render_size()[0] < self.width or self.render_size()[1] < self.height:
            raise ValueError(f"render={self.render!r} is smaller than the observation {self.width}x{self.height}")
        return self

    def render_size(self) -> tuple[int, int]:
        """(width, height) the engine renders at."""
        if self.render == "auto":
            for w, h in RESOLUTIONS_16_9:
                if w >= self.width and h >= self.height:
                    return w, h
            return RESOLUTIONS_16_9[-1]
        w, h = self.render.split("x")
        return int(w), int(h)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class HouseConfig(DoomConfig):
    """The House environment `emml/House-v0` (Appendix C, Table 8): one fixed house of four rooms, the agent's spawn
    fixed, furniture at fixed slots in colours drawn per episode (emml/envs/house.py). Fields not redefined here
    mean what they mean in DoomConfig; the choices where the paper is silent are in docs/fidelity.md."""

    difficulty: str = "house"
    """Always 'house' (one fixed house, Appendix C); kept so run names and code written for DoomConfig read it."""
    max_steps: Positive = 420
    """Episode limit in agent steps (Appendix C: 'All episodes have a maximum length of 420 time steps')."""
    reach_distance: float = 8.0
    """An object is reached when the player's collision box comes within this many map units of the object's
    (paper silent; furniture differs in size, so not a centre distance as in the Doom room)."""
    shaping_coef: float = 0.00025
    """Shaping reward per map unit of decrease in the path distance (through the doorways) to the referent, in
    SGN and in EQA (Appendix C; paper silent on the scale: ~0.3 over the longest path, spawn to bed, 1,231 units).
    `shaping` turns it off."""
    dataset: str = "house"
    """Table 8 (emml/tasks/house.toml)."""

    GYM_ID: ClassVar[str] = HOUSE_ID
    DIFFICULTIES: ClassVar[tuple[str, ...]] = kinds_of(HOUSE_ID)


ENV_CONFIGS: dict[str, type[DoomConfig]] = {c.GYM_ID: c for c in (DoomConfig, HouseConfig)}
"""The config class of each environment, by gym id."""
ENV_DIFFICULTIES = tuple(ENV_KINDS)
"""Where a run trains: Doom Easy, Doom Hard (§4), or the House (Appendix C): the kinds of emml/config/env_kinds.py."""


def env_config_class(difficulty: str) -> type[DoomConfig]:
    """The environment config a difficulty needs: the class of its kind's gym id (HouseConfig for 'house',
    Appendix C); DoomConfig for a value that is no kind, so that `validate` names it."""
    kind = ENV_KINDS.get(difficulty)
    return ENV_CONFIGS[kind.gym_id] if kind is not None else DoomConfig


def match_env_class(env: DoomConfig) -> DoomConfig:
    """``env`` in the config class its difficulty needs (a run switched to 'house' by a profile or --set gets a
    HouseConfig); fields left at the old class's defaults take the new class's (the House's 420 steps, Table 8)."""
    cls = env_config_class(env.difficulty)
    if type(env) is cls:
        return env
    old, new = type(env)(), cls()
    values = {}
    for f in fields(cls):
        value = getattr(env, f.name)
        values[f.name] = getattr(new, f.name) if value == getattr(old, f.name) else value
    values["difficulty"] = env.difficulty
    return cls(**values)
