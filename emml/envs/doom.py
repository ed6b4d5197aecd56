"""`emml/Doom-v0`: the ViZDoom language-grounding tasks of Chaplot et al. (2019), SGN and EQA, Easy and Hard.

One room, 5 objects (§4 'Environments'). Easy: the agent starts at (128, 512) facing east, the objects stand at
x = 256, y ∈ {384, 448, 512, 576, 640}. Hard: the agent and the objects at random points at least
`HARD_SPACING` apart, inside the room less a margin, the agent facing one of four directions. Actions: forward,
turn left, turn right, answer (the answer word is the second action component, the argmax of the model's
answer distribution). Rewards follow §5.1; the choices where the paper is silent are DoomConfig fields.

Objects are placed exactly, per episode, with console commands executed in one tic: the player is warped to a
point from which `summon` spawns the object at its slot (summon puts it 2·radius + 16 units ahead), then warped
to its start.
"""

from __future__ import annotations

import math

import cv2
import gymnasium as gym
import numpy as np
from gymnasium import spaces

from emml.config.geometry import conv_output_size
from emml.config.schema import DoomConfig, config_from_dict
from emml.envs import engine as eng
from emml.envs.labels import LabelGrid, channel_mask, default_aux_words
from emml.envs.objects import ACTORS, iwad_path
from emml.envs.wad import ROOM, map_name, wad_path
from emml.tasks.episodes import Episode, sample_episode
from emml.tasks.language import TASKS, load_dataset, normalize, resolve_vocabulary

MOVES = ("forward", "left", "right", "answer")
FORWARD, LEFT, RIGHT, ANSWER = range(4)

EASY_START = (128, 512, 0)
"""(x, y, angle°) of the agent in Easy (the reference SGN room)."""
EASY_SLOTS = tuple((256, y) for y in (384, 448, 512, 576, 640))
"""The 5 fixed object positions in Easy, in the agent's view."""
HARD_MARGIN = 32
"""Hard: positions keep this distance from the walls (reference SGN environment)."""
HARD_SPACING = 90
"""Hard: minimum distance between any two of the agent and the objects (reference: Poisson-disc, 90)."""
PLAYER_RADIUS = 16
EPISODE_START_TICS = 10
"""The engine ignores input for the first ~8 tics of an episode (notes/vizdoom.md)."""


def sample_positions(rng: np.random.Generator, n: int) -> list[tuple[int, int]]:
    """``n`` integer points in the room less the margin, pairwise at least HARD_SPACING apart (dart throwing,
    restarted when stuck; each dart uniform in the free square)."""
    lo_x, hi_x = ROOM.x_min + HARD_MARGIN, ROOM.x_max - HARD_MARGIN
    lo_y, hi_y = ROOM.y_min + HARD_MARGIN, ROOM.y_max - HARD_MARGIN
    while True:
        points: list[tuple[int, int]] = []
        for _ in range(200):
            p = (int(rng.integers(lo_x, hi_x + 1)), int(rng.integers(lo_y, hi_y + 1)))
            if all(math.dist(p, q) >= HARD_SPACING for q in points):
                points.append(p)
                if len(points) == n:
                    return points


OBSERVATION_KEYS = {
    "image": "the agent's view, RGB, channels first",
    "tokens": "the instruction or question, word indices (0 pads), `max_words` long",
    "task": "0: SGN (go to the object named), 1: EQA (answer the question)",
    "time": "steps taken in the episode",
    "aux": "with `aux_labels`: per word, the conv3 cells showing an object it describes",
    "target": "with `target_in_obs`: the cells showing the referent (privileged; else `info['target_mask']`)",
}
"""What each observation key holds (the class docstring, docs/environment.md: `space_rows`)."""


def space_rows(env: DoomEnv) -> list[str]:
    """docs/environment.md's table of ``env``'s spaces, one markdown row per observation key, then the action:
    checked against that page by the tests, so the two cannot drift."""

    def spelled(space) -> str:
        if isinstance(space, spaces.MultiDiscrete):
            return f"MultiDiscrete({space.nvec.tolist()})"
        return repr(space)

    rows = [f"| `{k}` | `{spelled(v)}` | {OBSERVATION_KEYS[k]} |" for k, v in env.observation_space.spaces.items()]
    moves = ", ".join(f"{i} {m}" for i, m in enumerate(MOVES))
    rows.append(f"| action | `{spelled(env.action_space)}` | [move ({moves}), answer word (read on answer)] |")
    return rows


class DoomEnv(gym.Env):
    """The EMML Doom environment, `emml/Doom-v0`: the ViZDoom tasks of Chaplot et al. (2019), Easy and Hard.

    ## Description

    One room with 5 objects; each episode is an instruction to follow (SGN: "go to the smallest blue object") or a
    question to answer (EQA: "what color is the torch"), drawn from the split's sentences (Table 7). Easy: the
    agent starts at one pose and the objects stand side by side in view; Hard: the agent and the objects at random
    points, the agent facing one of four directions.

    ## Action Space

    `MultiDiscrete([4, V])` (V: the vocabulary's size): a move, 0 forward, 1 turn left, 2 turn right, 3 answer, and
    the answer word (a vocabulary index), read only when the move is 'answer' in an EQA episode. In SGN, 'answer'
    is a step that does not move.

    ## Observation Space

    A `Dict`: `image` `Box(0, 255, (3, height, width), uint8)`, the agent's view, RGB, channels first; `tokens`
    `Box(0, V, (max_words,), int64)`, the sentence's word indices (0 pads); `task` `Discrete(2)`, 0 SGN, 1 EQA;
    `time` `Discrete(max_steps + 1)`, the steps taken. With `aux_labels`: `aux` `Box(0, 1, (V, h, w), uint8)`, per
    word the conv3 cells (h × w) showing an object it describes (the auxiliary task's labels, §3.2). With
    `target_in_obs` (and `aux_labels`): `target` `Box(0, 1, (h, w), uint8)`, the cells showing the referent:
    privileged, for the 'target_mask' diagnostic control; otherwise it is `info['target_mask']`.

    ## Rewards

    +1 (`success_reward`) for reaching the object named (SGN) or answering right (EQA), `wrong_reward` (0) for
    reaching another object or answering wrongly, -0.001 (`step_reward`) every step, and in SGN, with `shaping`,
    `shaping_coef` per map unit of decrease in the distance to the referent (§5.1).

    ## Starting State

    Easy: the agent at (128, 512) facing east, the objects at x = 256, y ∈ {384, 448, 512, 576, 640}. Hard: the
    agent and the objects at points drawn in the room at least `HARD_SPACING` apart, the agent facing one of four
    directions. The sentence is drawn uniformly in the split (SGN or EQA 50/50 when `tasks` is 'both'), or given by
    ``reset(options={"sentence": text})``.

    ## Episode End

    Terminated: SGN, when the agent comes within `reach_distance` of any object (success if it is the referent);
    EQA, at the first 'answer'. Truncated: after `max_steps` steps (210, §5.1). `gym.make` also wraps the env in
    `TimeLimit` with the spec's `max_episode_steps`, the same 210: both end the episode at the same step; a run
    with a longer `max_steps` passes `max_episode_steps` too.

    ## Arguments

    The keyword arguments of `DoomConfig` (emml/config/env.py), or ``config=DoomConfig(...)``; e.g.
    ``gym.make("emml/Doom-v0", difficulty="hard", split="test", tasks="sgn", aux_labels=True)``. The main ones:
    `difficulty` ('easy', 'hard'), `split` ('train', 'test'), `tasks` ('both', 'sgn', 'eqa'), `height` and `width`
    (168 × 300), `aux_labels`, `target_in_obs`, `max_steps`, `shaping`. ``render_mode='rgb_array'`` renders the
    observed frame.

    ## Info

    `task`, `answer` (the answer word's index, -1 in SGN), `success`, `text` (the sentence), `target` (the
    referent's name) and, with `aux_labels`, `target_mask`.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 35 / 5}
    objects_info = False
    """Ask the engine for every actor's position (``state.objects``): off for speed; tests turn it on."""
    shaped_tasks: tuple[str, ...] = ("sgn",)
    """The tasks whose reward is shaped by the decrease in `_target_distance` (when `shaping` is on): SGN only in
    Doom (§5.1; docs/fidelity.md 'Shaping')."""

    def __init__(self, config: DoomConfig | None = None, render_mode: str | None = None, **kwargs):
        cfg = config if config is not None else config_from_dict(DoomConfig, kwargs)
        self.cfg = cfg.validate()
        self.render_mode = render_mode
        self.dataset = load_dataset(cfg.dataset)
        self.vocab = resolve_vocabulary(cfg.vocabulary, self.dataset)
        self.sentences = {k: self.dataset.select(k, cfg.split) for k in cfg.played}
        if cfg.instructions:
            wanted = [self.dataset.find(t) for t in cfg.instructions]
            for s in wanted:
                if s.split != cfg.split or s.kind not in cfg.played:
                    raise ValueError(
                        f"instructions: {s.text!r} is a {s.split} {s.kind} sentence, not in split={cfg.split!r} "
                        f"tasks={cfg.tasks!r}"
                    )
            self.sentences = {k: tuple(s for s in wanted if s.kind == k) for k in cfg.played}
            self.sentences = {k: v for k, v in self.sentences.items() if v}
        for sents in self.sentences.values():
            for s in sents:
                self.vocab.encode(s.text, cfg.max_words)  # every word known, and it fits: fail now, not mid-run
        self.grid_hw = conv_output_size(cfg.height, cfg.width)
        self.aux_words = (
            tuple(cfg.aux_words) if cfg.aux_words is not None else default_aux_words(self.vocab, self.dataset)
        )
        self.aux_mask = channel_mask(self.vocab, self.aux_words)
        """bool (V,): the channels the aux labels supervise (all but the superlatives, by default)."""
        self.render_wh = cfg.render_size()

        V = len(self.vocab)
        obs = {
            "image": spaces.Box(0, 255, (3, cfg.height, cfg.width), np.uint8),
            "tokens": spaces.Box(0, V, (cfg.max_words,), np.int64),
            "task": spaces.Discrete(2),
            "time": spaces.Discrete(cfg.max_steps + 1),
        }
        if cfg.aux_labels:
            obs["aux"] = spaces.Box(0, 1, (V, *self.grid_hw), np.uint8)
        if cfg.target_in_obs:
            # the cells showing the episode's referent: privileged, read only by the diagnostics and the
            # 'target_mask' control (emml/eval/diagnose.py), never by a model under the paper's protocol; else
            # they are info['target_mask']
            obs["target"] = spaces.Box(0, 1, self.grid_hw, np.uint8)
        self.observation_space = spaces.Dict(obs)
        self.action_space = spaces.MultiDiscrete([len(MOVES), V])
        self._labels = (
            LabelGrid(
                self.vocab,
                self.dataset,
                self.aux_words,
                self.render_wh[::-1],
                self.grid_hw,
                (cfg.height, cfg.width) if cfg.label_grid == "receptive_field" else None,
            )
            if cfg.aux_labels
            else None
        )
        self._interp = {"area": cv2.INTER_AREA, "linear": cv2.INTER_LINEAR, "nearest": cv2.INTER_NEAREST}[
            cfg.interpolation
        ]
        self._turn = cfg.turn_degrees / cfg.frame_skip
        self._engine: eng.Engine | None = None
        self._map: str | None = None
        self.episode: Episode | None = None

    # --- engine -------------------------------------------------------------------------------------------
    def _scenario(self):
        """The WAD the engine loads and the map it starts on (the House env gives its own)."""
        return wad_path(), map_name(0)

    def _game(self):
        if self._engine is None:
            import vizdoom as vzd

            g = vzd.DoomGame()
            scenario, first_map = self._scenario()
            g.set_doom_game_path(str(iwad_path()))
            g.set_doom_scenario_path(str(scenario))
            g.set_doom_map(first_map)
            w, h = self.render_wh
            g.set_screen_resolution(getattr(vzd.ScreenResolution, f"RES_{w}X{h}"))
            g.set_screen_format(vzd.ScreenFormat.CRCGCB)  # planar 3×H×W: no transpose needed
            g.set_labels_buffer_enabled(self.cfg.aux_labels)
            g.set_objects_info_enabled(self.objects_info)
            for setter in ("hud", "weapon", "crosshair", "decals", "particles", "messages", "corpses"):
                getattr(g, f"set_render_{setter}")(False)
            g.set_available_buttons([vzd.Button.MOVE_FORWARD, vzd.Button.TURN_LEFT_RIGHT_DELTA])
            g.set_available_game_variables(
                [vzd.GameVariable.POSITION_X, vzd.GameVariable.POSITION_Y, vzd.GameVariable.ANGLE]
            )
            g.set_episode_start_time(EPISODE_START_TICS)
            g.set_episode_timeout(0)
            g.set_window_visible(False)
            g.set_sound_enabled(False)
            g.set_mode(vzd.Mode.PLAYER)
            g.add_game_args("+sv_cheats 1")
            self._engine = eng.start_engine(g)
        return self._engine.game

    def _call(self, fn, *args):
        try:
            return fn(*args)
        except Exception as e:
            pid = self._engine.pid if self._engine else None
            self.close()
            raise eng.EngineError(f"ViZDoom engine (pid {pid}) failed: {type(e).__name__}: {e}") from e

    # --- episode --------------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """A new episode. ``options={"sentence": text}`` plays that instruction or question (one of this env's
        sentences) instead of drawing one; the scene is drawn as usual (`_draw_scene`)."""
        super().reset(seed=seed)
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
        doom_map, (ax, ay, angle) = self._draw_scene(sentence, rng)
        game = self._game()
        if seed is not None:
            game.set_seed(int(seed) & 0xFFFFFFFF)  # engine-side randomness (animations) follows the seed too
        if doom_map != self._map:
            game.set_doom_map(doom_map)
            self._map = doom_map
        self._call(game.new_episode)
        c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
        for name, (x, y) in zip(self.episode.scene, self.positions):
            radius, spawn_class = self._actor(name)
            ahead = 2 * radius + PLAYER_RADIUS  # where summon puts it, ahead of the player
            game.send_game_command(f"warp {round(x - ahead * c)} {round(y - ahead * s)}")
            game.send_game_command(f"summon {spawn_class}")
        game.send_game_command(f"warp {ax} {ay}")
        self._call(game.advance_action, 1)  # the commands run in this one tic
        self.t = 0
        self.ended = False
        self.tokens = np.array(self.vocab.encode(sentence.text, self.cfg.max_words), dtype=np.int64)
        self.task_id = TASKS.index(sentence.kind)
        self.answer_id = self.vocab.index(self.episode.answer) if self.episode.answer else -1
        self._read_state()
        self._dist = self._target_distance()
        return self._obs(), self._info(False)

    def _chosen(self, text: str):
        """The env's sentence with this text (reset's ``sentence`` option)."""
        for pool in self.sentences.values():
            for s in pool:
                if s.text == normalize(text):
                    return s
        allowed = [s.text for pool in self.sentences.values() for s in pool]
        raise ValueError(f"reset option sentence={text!r} is not one of this env's sentences: {allowed}")

    def step(self, action):
        if self._engine is None and self.episode is not None:
            raise RuntimeError("step() after close(): this env is closed; make a new one")
        if self.episode is None:
            raise RuntimeError("call reset() before step()")
        if self.ended:  # Gymnasium's convention: a finished episode pays nothing more
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
            if TASKS[self.task_id] in self.shaped_tasks:
                d = self._target_distance()
                if cfg.shaping:
                    reward += cfg.shaping_coef * (self._dist - d)
                self._dist = d
            if self.task_id == 0 and (reached := self._reached()) is not None:  # SGN ends at any object
                terminated = True
                success = reached
                reward += cfg.success_reward if success else cfg.wrong_reward
        self.t += 1
        truncated = not terminated and self.t >= cfg.max_steps
        self.ended = terminated or truncated
        return self._obs(), float(reward), terminated, truncated, self._info(success)

    # --- what an env kind overrides (the House: emml/envs/house.py) -------------------------------------------
    def _draw_scene(self, sentence, rng: np.random.Generator) -> tuple[str, tuple[int, int, int]]:
        """Draw the episode of ``sentence`` (sets `episode` and `positions`, the actors' points in scene order):
        returns the map to play and the agent's start (x, y, angle°). Easy: the fixed start and slots; Hard:
        random points and one of four directions (§4 'Environments')."""
        self.episode = sample_episode(sentence, self.dataset, rng)
        if self.cfg.difficulty == "easy":
            start = EASY_START
            self.positions = list(EASY_SLOTS)
        else:
            pts = sample_positions(rng, 6)
            (ax, ay), self.positions = pts[0], pts[1:]
            start = (ax, ay, int(rng.choice([0, 90, 180, 270])))
        return map_name(start[2]), start

    def _actor(self, name: str) -> tuple[float, str]:
        """(collision radius, spawn class) of the scene's actor ``name``: what `summon` places at its point."""
        actor = ACTORS[name]
        return actor.radius, actor.spawn_class

    def _target_distance(self) -> float:
        """The distance whose decrease shapes the reward: straight-line, agent to the target's centre (§5.1)."""
        return self._distances()[self.episode.target]

    def _reached(self) -> bool | None:
        """SGN's reach test: None while no object is within `reach_distance` (centre distance); else whether the
        nearest one is the target."""
        dists = self._distances()
        nearest = int(np.argmin(dists))
        if dists[nearest] <= self.cfg.reach_distance:
            return nearest == self.episode.target
        return None

    # --- observation ------------------------------------------------------------------------------------------
    def _read_state(self):
        state = self._engine.game.get_state()
        self.state = state
        if state is None:
            raise eng.EngineError("ViZDoom returned no state: the episode ended inside the engine")
        self.pose = tuple(float(v) for v in state.game_variables)
        frame = state.screen_buffer  # 3×h×w
        if frame.shape[1] != self.cfg.height or frame.shape[2] != self.cfg.width:
            out = np.empty((3, self.cfg.height, self.cfg.width), dtype=np.uint8)
            for c in range(3):  # per plane: cheaper than resizing H×W×3 and transposing
                cv2.resize(frame[c], (self.cfg.width, self.cfg.height), dst=out[c], interpolation=self._interp)
            frame = out
        self.frame = frame
        self.aux = None
        if self._labels:
            self.aux = self._labels(state.labels_buffer, state.labels)
            target = self.episode.scene[self.episode.target]
            self.target_grid = self._labels.object_grid(state.labels_buffer, state.labels, target)

    def scene_grids(self) -> np.ndarray:
        """uint8 (5, h, w): the cells showing each actor of the scene in the current frame, in scene order (the
        referent is row `episode.target`). Privileged, like the aux labels: for the diagnostics
        (emml/eval/diagnose_eqa.py); needs ``aux_labels``."""
        if self._labels is None:
            raise RuntimeError("scene_grids() reads the label buffer: make the env with aux_labels=True")
        buf, labels = self.state.labels_buffer, self.state.labels
        return np.stack([self._labels.object_grid(buf, labels, name) for name in self.episode.scene])

    def _distances(self) -> np.ndarray:
        x, y = self.pose[0], self.pose[1]
        return np.array([math.hypot(px - x, py - y) for px, py in self.positions])

    def _obs(self) -> dict:
        obs = {
            "image": self.frame,
            "tokens": self.tokens.copy(),
            "task": self.task_id,
            "time": min(self.t, self.cfg.max_steps),
        }
        if self.aux is not None:
            obs["aux"] = self.aux
            if self.cfg.target_in_obs:
                obs["target"] = self.target_grid
        return obs

    def _info(self, success: bool) -> dict:
        info = {
            "task": self.task_id,
            "answer": self.answer_id,
            "success": bool(success),
            "text": self.episode.sentence.text,
            "target": self.episode.scene[self.episode.target],
        }
        if self.aux is not None:
            info["target_mask"] = self.target_grid
        return info

    def render(self):
        return None if self.render_mode is None else np.ascontiguousarray(self.frame.transpose(1, 2, 0))

    def close(self):
        with eng.signals_held():  # an interrupt must not drop the engine between these lines
            if self._engine is not None:
                engine, self._engine = self._engine, None
                eng.end_engine(engine)
            self._map = None
