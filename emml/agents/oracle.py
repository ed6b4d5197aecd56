"""A scripted expert with privileged state (object and agent poses): proof that every episode is solvable.

SGN: turn towards the target (or towards a detour point when another object lies near the straight path, since
touching any object ends the episode), walk when the heading is within half a turn step. EQA: answer with the
correct word at once (it knows the scene).
"""

from __future__ import annotations

import math

import numpy as np

from emml.envs.doom import ANSWER, FORWARD, LEFT, RIGHT, DoomEnv
from emml.envs.wad import ROOM

CLEARANCE = 64.0
"""Keep other objects' centres this far from the path: reach distance 40 plus the drift of the player's momentum
while it turns. Objects closer to the target than that (Easy slots are 64 apart) get what room there is."""
TIGHT_CLEARANCE = 46.0
"""The fallback when no comfortable way exists: just beyond the reach distance."""


def _segment_distance(p, a, b) -> float:
    ab = np.subtract(b, a)
    t = float(np.clip(np.dot(np.subtract(p, a), ab) / max(np.dot(ab, ab), 1e-9), 0.0, 1.0))
    return math.dist(p, np.add(a, t * ab))


def _clear(a, b, obstacles, target, clearance=CLEARANCE) -> bool:
    """No obstacle nearer the segment a→b than the clearance (or than it already is to a, or to the target)."""
    return all(
        _segment_distance(o, a, b) > min(clearance, math.dist(o, target) - 6, math.dist(o, a) - 2) for o in obstacles
    )


def waypoint(agent, target, obstacles) -> tuple[float, float]:
    """The point to head for: the target if the way is clear, else the shortest detour beside a blocker whose
    both legs are clear. Tried with the comfortable clearance first, then with a tight one (through gaps)."""
    for clearance in (CLEARANCE, TIGHT_CLEARANCE):
        if _clear(agent, target, obstacles, target, clearance):
            return target
        best, best_cost = None, math.inf
        for o in obstacles:
            for radius in (70.0, 100.0):
                for k in range(16):
                    a = 2 * math.pi * k / 16
                    w = (o[0] + radius * math.cos(a), o[1] + radius * math.sin(a))
                    inside = ROOM.x_min + 20 < w[0] < ROOM.x_max - 20 and ROOM.y_min + 20 < w[1] < ROOM.y_max - 20
                    if (
                        inside
                        and _clear(agent, w, obstacles, target, clearance)
                        and _clear(w, target, obstacles, target, clearance)
                    ):
                        cost = math.dist(agent, w) + math.dist(w, target)
                        if cost < best_cost:
                            best, best_cost = w, cost
        if best is not None:
            return best
    return target


class Oracle:
    """Acts in a DoomEnv (unwrapped) from its privileged state."""

    def __init__(self, env: DoomEnv):
        self.env = env
        self._episode = None
        self._detour = None  # the detour point it is heading for, kept until reached (replanning every step dithers)

    def act(self) -> np.ndarray:
        env = self.env
        ep = env.episode
        if env.task_id == 1:
            return np.array([ANSWER, env.answer_id])
        x, y, angle = env.pose
        target = env.positions[ep.target]
        obstacles = [p for i, p in enumerate(env.positions) if i != ep.target]
        if ep is not self._episode:
            self._episode, self._detour = ep, None
        if self._detour is not None and (
            math.dist((x, y), self._detour) < 20 or _clear((x, y), target, obstacles, target)
        ):
            self._detour = None
        if self._detour is None:
            w = waypoint((x, y), target, obstacles)
            self._detour = None if w == target else w
        wx, wy = self._detour or target
        want = math.degrees(math.atan2(wy - y, wx - x))
        error = (want - angle + 180) % 360 - 180  # >0: target is to the left (angles grow counter-clockwise)
        if abs(error) <= env.cfg.turn_degrees / 2:
            return np.array([FORWARD, 0])
        return np.array([LEFT if error > 0 else RIGHT, 0])


def run_oracle(env: DoomEnv, episodes: int, seed: int = 0) -> dict:
    """Accuracy of the oracle over ``episodes`` episodes: fraction ending in success, and mean steps. A HouseEnv
    gets the house's path-planning oracle (emml/agents/house_oracle.py)."""
    from emml.envs.house import HouseEnv

    if isinstance(env, HouseEnv):
        from emml.agents.house_oracle import HouseOracle

        oracle = HouseOracle(env)
    else:
        oracle = Oracle(env)
    successes, steps, failures = 0, [], []
    for i in range(episodes):
        env.reset(seed=seed + i)
        for _ in range(env.cfg.max_steps):
            _, _, terminated, truncated, info = env.step(oracle.act())
            if terminated or truncated:
                break
        successes += info["success"]
        steps.append(env.t)
        if not info["success"]:
            failures.append({"seed": seed + i, "text": info["text"], "scene": list(env.episode.scene)})
    return {
        "episodes": episodes,
        "accuracy": successes / episodes,
        "mean_steps": float(np.mean(steps)),
        "max_steps": int(np.max(steps)),
        "failures": failures[:10],
    }
