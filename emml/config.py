"""Dataclass configs. Every field has a docstring with its unit and source (paper section, or 'our choice' with
the reason, collected in docs/fidelity.md). `validate()` fails before any compute with the field's name and the
allowed values."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields

from emml.tasks.language import check_choice

RESOLUTIONS_16_9 = ((256, 144), (320, 180), (400, 225), (512, 288), (640, 360), (800, 450), (1024, 576))
"""ViZDoom's 16:9 screen resolutions (width, height), the aspect of the paper's 300×168 input."""


@dataclass
class DoomConfig:
    """The Doom environment `emml/Doom-v0` (paper §4 'Environments', §5.1, Appendix B)."""

    difficulty: str = "easy"
    """'easy': agent fixed, objects at 5 fixed slots in view; 'hard': random agent pose and object positions."""
    split: str = "train"
    """'train' or 'test' instructions/questions (Table 7)."""
    tasks: str = "both"
    """'both' (SGN and EQA, 50/50 per episode), 'sgn' or 'eqa' (single-task ablation, Table 3)."""
    height: int = 168
    """Observation height in pixels (Appendix A: 3×168×300)."""
    width: int = 300
    """Observation width in pixels (Appendix A)."""
    aux_labels: bool = False
    """Add the V×h×w auxiliary detection labels ('aux') to the observation (§3.2 'Auxiliary Task')."""
    max_steps: int = 210
    """Episode limit in agent steps (§5.1: 'maximum length of 210 time steps')."""
    frame_skip: int = 5
    """Engine tics per agent step (paper silent; the reference SGN environment repeats each action 5 tics)."""
    turn_degrees: float = 15.0
    """Turn per left/right step, in degrees (paper silent; our choice: 3°/tic × 5 tics, 24 steps a full turn)."""
    reach_distance: float = 40.0
    """An object is reached within this 2-D distance of its centre, map units (reference SGN environment)."""
    success_reward: float = 1.0
    """Reaching the right object (SGN) or answering correctly (EQA) (§5.1)."""
    step_reward: float = -0.001
    """Every step (§5.1)."""
    wrong_reward: float = -0.2
    """Reaching a wrong object or answering wrongly (paper silent; the SGN environment it adapts uses -0.2)."""
    shaping: bool = True
    """Distance-based reward shaping in SGN (§5.1; off for the 'w/o reward shaping' ablation, Table 3)."""
    shaping_coef: float = 0.001
    """Shaping reward per map unit of decrease in distance to the target (paper silent: 'small'; ~0.1 per Easy
    episode)."""
    render: str = "auto"
    """ViZDoom render resolution 'WxH' (16:9); 'auto' takes the smallest one at least the observation size."""
    interpolation: str = "area"
    """Resize filter from render to observation size: 'area' (the reference env's cv2.INTER_AREA), 'linear'."""
    max_words: int = 10
    """Token sequence length (padded with 0)."""
    vocabulary: tuple[str, ...] | None = None
    """The run's vocabulary (channel order); None builds the default: every word of the dataset."""
    aux_words: tuple[str, ...] | None = None
    """Words that get aux labels; None: every object, colour and size word in the vocabulary (no labels for
    superlatives — §3.2 — nor for function words). The transfer experiment passes the training words only."""
    instructions: tuple[str, ...] | None = None
    """Restrict episodes to these sentences (must be in the chosen split); None: all of the split."""
    dataset: str = "doom"
    """Which tasks/<name>.toml."""

    def validate(self) -> DoomConfig:
        check_choice("difficulty", self.difficulty, ("easy", "hard"))
        check_choice("split", self.split, ("train", "test"))
        check_choice("tasks", self.tasks, ("both", "sgn", "eqa"))
        check_choice("interpolation", self.interpolation, ("area", "linear", "nearest"))
        from emml.geometry import conv_output_size

        conv_output_size(self.height, self.width)  # raises naming height/width when too small
        for name in ("max_steps", "frame_skip", "max_words"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name}={getattr(self, name)!r} must be a positive integer")
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


def config_from_dict(cls, values: dict):
    """Build a config dataclass from a dict, rejecting unknown keys by name (tuples restored from lists)."""
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown {cls.__name__} field(s) {unknown}; known fields: {sorted(known)}")
    fixed = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    return cls(**fixed)


__all__ = ["DoomConfig", "config_from_dict", "RESOLUTIONS_16_9", "field"]
