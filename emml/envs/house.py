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

import math

import gymnasium as gym
import numpy as np

from emml.config import HouseConfig, config_from_dict
from emml.envs.doom import ANSWER, FORWARD, LEFT, MOVES, RIGHT, TASKS, DoomEnv
from emml.envs.furniture import CLASS_TO_ACTOR, FURNITURE, spawn_class
from emml.envs.house_wad import HOUSE, MAP, wad_path
from emml.envs.navigation import PLAYER_RADIUS, distance_at, shaping_fields, shaping_grid
from emml.tasks.episodes import sample_colours
from emml.tasks.language import referents

__all__ = ["ANSWER", "FORWARD", "LEFT", "MOVES", "RIGHT", "HouseEnv"]


class HouseEnv(DoomEnv):
    """The EMML House environment. Construct with keyword arguments of `HouseConfig` (or ``config=``)."""

    house = HOUSE
    """The fixed house (rooms, doorways, furniture slots, spawn)."""

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

    # --- episode --------------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """A new episode. ``options={"sentence": text}`` plays that instruction or question (one of this env's
        sentences) instead of drawing one; the colours are drawn as usual."""
        gym.Env.reset(self, seed=seed)
        rng = self.np_random
        unknown = sorted(set(options or {}) - {"sentence"})
        if unknown:
            raise ValueError(f"reset options {unknown} are unknown; allowed: 'sentence'")
        if options and options.get("sentence") is not None:
            sentence = self._chosen(options["sentence"])
        else:
            kinds = tuple(self.sentences)
            kind = kinds[int(rng.integers(len(kinds)))]  # 50/50 when both tasks are on
            pool = self.sentences[kind]
            sentence = pool[int(rng.integers(len(pool)))]  # uniform in the split
        self.episode = sample_colours(sentence, self.dataset, self.slot_objects, rng)
        self.targets = tuple(referents(sentence, self.episode.scene, self.dataset))
        game = self._game()
        if seed is not None:
            game.set_seed(int(seed) & 0xFFFFFFFF)
        if self._map != MAP:
            game.set_doom_map(MAP)
            self._map = MAP
        self._call(game.new_episode)
        ax, ay, angle = self.house.spawn
        c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
        for name, slot in zip(self.episode.scene, self.house.slots):
            actor = self.dataset.actors[name]
            ahead = 2 * FURNITURE[actor.object].radius + PLAYER_RADIUS  # where summon puts it, ahead of the player
            game.send_game_command(f"warp {round(slot.x - ahead * c)} {round(slot.y - ahead * s)}")
            game.send_game_command(f"summon {spawn_class(actor.object, actor.color)}")
        game.send_game_command(f"warp {ax} {ay}")
        self._call(game.advance_action, 1)  # the commands run in this one tic
        self.t = 0
        self.ended = False
        self.tokens = np.array(self.vocab.encode(sentence.text, self.cfg.max_words), dtype=np.int64)
        self.task_id = TASKS.index(sentence.kind)
        self.answer_id = self.vocab.index(self.episode.answer) if self.episode.answer else -1
        self._read_state()
        self._dist = self.target_distance()
        return self._obs(), self._info(False)

    def step(self, action):
        if self._engine is None and self.episode is not None:
            raise RuntimeError("step() after close(): this env is closed; make a new one")
        if self.episode is None:
            raise RuntimeError("call reset() before step()")
        if self.ended:
            raise RuntimeError("step() after the episode ended (terminated or truncated): call reset() first")
        arr = np.asarray(action)
        if not self.action_space.contains(arr):
            raise ValueError(
                f"action {action!r}: expected two integers [move, word], move in 0..{len(MOVES) - 1} "
                f"({', '.join(MOVES)}) and word in 0..{len(self.vocab) - 1} (a vocabulary index, read on 'answer')"
            )
        move, word = int(arr[0]), int(arr[1])
        cfg, game = self.cfg, self._engine.game
        reward, terminated, success = cfg.step_reward, False, False
        if move == ANSWER and self.task_id == 1:  # EQA: any answer ends the episode
            terminated = True
            success = word == self.answer_id
            reward += cfg.success_reward if success else cfg.wrong_reward
        else:
            buttons = {FORWARD: [1, 0], LEFT: [0, -self._turn], RIGHT: [0, self._turn], ANSWER: [0, 0]}[move]
            self._call(game.make_action, buttons, cfg.frame_skip)  # SGN: 'answer' is a no-op step
            self._read_state()
            d = self.target_distance()
            if cfg.shaping:  # Appendix C: shaping in SGN and EQA episodes alike
                reward += cfg.shaping_coef * (self._dist - d)
            self._dist = d
            if self.task_id == 0:
                gaps = self.gaps()
                nearest = int(np.argmin(gaps))
                if gaps[nearest] <= cfg.reach_distance:  # SGN ends at any object
                    terminated = True
                    success = nearest in self.targets
                    reward += cfg.success_reward if success else cfg.wrong_reward
        self.t += 1
        truncated = not terminated and self.t >= cfg.max_steps
        self.ended = terminated or truncated
        return self._obs(), float(reward), terminated, truncated, self._info(success)

    # --- geometry -------------------------------------------------------------------------------------------
    def gaps(self) -> np.ndarray:
        """float (7,): per slot, the gap between the player's collision box and the piece's (0 when touching)."""
        x, y = self.pose[0], self.pose[1]
        return np.maximum(np.abs(self._xy[:, 0] - x), np.abs(self._xy[:, 1] - y)) - self._half

    def target_distance(self) -> float:
        """Path distance (through the doorways) from the agent to the nearest referent's centre."""
        x, y = self.pose[0], self.pose[1]
        return min(distance_at(self._grid, self._fields[i], x, y) for i in self.targets)
