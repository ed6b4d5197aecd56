"""`emml/House-v0`: the House domain of Chaplot et al. (2019), Appendix C, rebuilt in ViZDoom.

One fixed house (emml/envs/house_wad.py: kitchen, study, living room, bedroom joined by doorways), the agent
spawning at a fixed pose, 7 furniture slots of the 6 classes of Table 8 whose colours are drawn every episode so
that the sentence has one referent (SGN) or one answer (EQA) (`sample_colours`). Observation and action spaces,
aux labels and the engine's lifecycle are those of `emml/Doom-v0` (this class extends DoomEnv).

Rewards (Appendix C): +1 for reaching the right object (SGN) or answering right (EQA), −0.001 per step, and
distance shaping in both tasks proportional to the decrease in the *path* distance to the referent (through the
doorways: emml/envs/navigation.py). SGN ends at any object, EQA at any answer; 420 steps at most.
"""

from __future__ import annotations

import numpy as np

from emml.config.schema import TASKS, HouseConfig, config_from_dict
from emml.envs.doom import ANSWER, FORWARD, LEFT, MOVES, RIGHT, DoomEnv
from emml.envs.furniture import CLASS_TO_ACTOR, FURNITURE, spawn_class
from emml.envs.house_wad import HOUSE, MAP, wad_path
from emml.envs.navigation import PLAYER_RADIUS, distance_at, shaping_fields, shaping_grid
from emml.tasks.episodes import sample_colours
from emml.tasks.language import referents

__all__ = ["ANSWER", "FORWARD", "LEFT", "MOVES", "RIGHT", "HouseEnv"]


class HouseEnv(DoomEnv):
    """The EMML House environment, `emml/House-v0`: Appendix C's House domain, rebuilt in ViZDoom.

    ## Description

    One fixed house of four rooms joined by doorways (kitchen, study, living room, bedroom) with 7 pieces of
    furniture of the 6 classes of Table 8, their colours drawn every episode so that the sentence has one referent
    (SGN) or one answer (EQA). Instructions and questions are Table 8's.

    ## Action Space

    As `emml/Doom-v0`: `MultiDiscrete([4, V])`, a move (forward, turn left, turn right, answer) and the answer word.

    ## Observation Space

    As `emml/Doom-v0` (the House's vocabulary: V = 18): `image`, `tokens`, `task`, `time` (`Discrete(421)`), with
    `aux_labels` `aux`, and with `target_in_obs` `target` (else `info['target_mask']`).

    ## Rewards

    +1 for reaching the referent (SGN) or answering right (EQA), -0.001 every step, and in both tasks, with
    `shaping`, `shaping_coef` per map unit of decrease in the *path* distance (through the doorways) to the
    referent (Appendix C).

    ## Starting State

    The agent at the house's fixed spawn; the furniture at its slots in colours drawn for the sentence.

    ## Episode End

    Terminated: SGN, when the agent's collision box comes within `reach_distance` of a piece's (success if it is a
    referent); EQA, at the first 'answer'. Truncated: after `max_steps` steps (420, Appendix C), the spec's
    `max_episode_steps` too.

    ## Arguments

    The keyword arguments of `HouseConfig` (or ``config=HouseConfig(...)``): those of `emml/Doom-v0` but
    `difficulty`, which is 'house'.
    """

    house = HOUSE
    """The fixed house (rooms, doorways, furniture slots, spawn)."""
    shaped_tasks = TASKS
    """Appendix C: shaping by the decrease in path distance to the referent in SGN and EQA episodes alike."""

    def __init__(self, config: HouseConfig | None = None, render_mode: str | None = None, **kwargs):
        cfg = config if config is not None else config_from_dict(HouseConfig, kwargs)
        if not isinstance(cfg, HouseConfig):
            raise TypeError(f"config must be a HouseConfig, not {type(cfg).__name__}")
        super().__init__(cfg, render_mode)
        if self._labels is not None:
            self._labels.class_to_actor = CLASS_TO_ACTOR
        self.slot_objects = tuple(s.object for s in self.house.slots)
        """Class word of each slot; an episode's scene[i] is the actor at slot i."""
        self.positions = [(s.x, s.y) for s in self.house.slots]
        self._half = np.array([FURNITURE[o].radius for o in self.slot_objects], dtype=np.float64) + PLAYER_RADIUS
        self._xy = np.array(self.positions, dtype=np.float64)
        self._grid = shaping_grid(self.house)
        self._fields = shaping_fields(self.house)
        self.targets: tuple[int, ...] = ()
        """Slots of every referent of the episode's sentence (two for a question about both sofas)."""

    def _scenario(self):
        return wad_path(self.house), MAP

    # --- what the House overrides of DoomEnv: the scene, the distance, the reach test ------------------------
    def _draw_scene(self, sentence, rng: np.random.Generator) -> tuple[str, tuple[int, int, int]]:
        """Colours drawn so that the sentence has one referent or one answer (Appendix C, `sample_colours`); the
        furniture stays at its slots and the agent at the fixed spawn."""
        self.episode = sample_colours(sentence, self.dataset, self.slot_objects, rng)
        self.targets = tuple(referents(sentence, self.episode.scene, self.dataset))
        return MAP, self.house.spawn

    def _actor(self, name: str) -> tuple[float, str]:
        actor = self.dataset.actors[name]
        return FURNITURE[actor.object].radius, spawn_class(actor.object, actor.color)

    def _target_distance(self) -> float:
        return self.target_distance()

    def _reached(self) -> bool | None:
        """SGN's reach test on the collision boxes (`gaps`, HouseConfig.reach_distance): None while no piece is
        in reach; else whether the nearest is a referent (either sofa of a sentence naming both)."""
        gaps = self.gaps()
        nearest = int(np.argmin(gaps))
        if gaps[nearest] <= self.cfg.reach_distance:
            return nearest in self.targets
        return None

    # --- geometry -------------------------------------------------------------------------------------------
    def gaps(self) -> np.ndarray:
        """float (7,): per slot, the gap between the player's collision box and the piece's (0 when touching)."""
        x, y = self.pose[0], self.pose[1]
        return np.maximum(np.abs(self._xy[:, 0] - x), np.abs(self._xy[:, 1] - y)) - self._half

    def target_distance(self) -> float:
        """Path distance (through the doorways) from the agent to the nearest referent's centre."""
        x, y = self.pose[0], self.pose[1]
        return min(distance_at(self._grid, self._fields[i], x, y) for i in self.targets)
