"""A scripted expert for the House domain (Appendix C) with privileged state and path planning.

It plans on the house grid (emml/envs/navigation.py) with a wider clearance than the player's own and with every
other piece of furniture as a blocker (touching any piece ends an SGN episode): a distance field to the cells from
which the referent counts as reached. Each step it follows the field downhill to the farthest point it can walk to
in a straight line (at most LOOKAHEAD away), turns towards it, and walks when the heading is within half a turn.
EQA: it walks towards the (nearer) referent until the piece is in plain view — no wall between, near the centre of
the view, close enough — then answers: proof that every question can be answered from a view of the house.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from emml.envs.furniture import FURNITURE
from emml.envs.house import ANSWER, FORWARD, LEFT, RIGHT, HouseEnv
from emml.envs.house_wad import House
from emml.envs.navigation import PLAYER_RADIUS, NavGrid, distance_at, distance_field, nav_grid

WALL_CLEARANCE = 28.0
"""Plan with the player's box this far from the walls (16 is touching): room for its momentum in turns."""
OBSTACLE_MARGIN = 20.0
"""Keep this much beyond the reach distance from every other piece's box."""
GOAL_SLACK = 3.0
"""Head for the cells whose box gap to the referent is the reach distance less this."""
LOOKAHEAD = 160.0
"""The farthest waypoint along the planned path, map units."""
SEE_HALF_ANGLE = 25.0
"""EQA: the referent's centre within this many degrees of the heading counts as in view."""
SEE_DISTANCE = 320.0
"""EQA: and within this many map units, with no wall on the line of sight."""


@functools.cache
def plan(house: House, target: int, reach: float) -> tuple[NavGrid, np.ndarray]:
    """(grid, distance field) towards slot ``target``: the other pieces blocked, goal = its reach region."""
    blockers = [
        (s.x, s.y, FURNITURE[s.object].radius + PLAYER_RADIUS + reach + OBSTACLE_MARGIN)
        for i, s in enumerate(house.slots)
        if i != target
    ]
    grid = nav_grid(house, WALL_CLEARANCE, blockers)
    t = house.slots[target]
    xs, ys = grid.centres()
    reach_half = FURNITURE[t.object].radius + PLAYER_RADIUS + reach - GOAL_SLACK
    goal = np.maximum(np.abs(xs - t.x), np.abs(ys - t.y)) <= reach_half
    return grid, distance_field(grid, goal)


@functools.cache
def sight_grid(house: House) -> NavGrid:
    """The house's open space (no clearance): a line of sight stays in it."""
    return nav_grid(house, 0.0)


def _descend(grid: NavGrid, field: np.ndarray, x: float, y: float, steps: int) -> list[tuple[float, float]]:
    """Cell centres along the field's steepest descent from the cell nearest (x, y) with a finite value."""
    i, j = grid.index(x, y)
    if not (grid.inside(i, j) and math.isfinite(field[i, j])):
        best = None
        for r in range(1, 8):  # drifted into a margin: start from the best cell close by
            cells = [
                (field[a, b] + math.dist((x, y), grid.centre(a, b)), a, b)
                for a in range(i - r, i + r + 1)
                for b in range(j - r, j + r + 1)
                if grid.inside(a, b) and math.isfinite(field[a, b])
            ]
            if cells:
                best = min(cells)
                break
        if best is None:
            return []
        i, j = best[1], best[2]
    path = [grid.centre(i, j)]
    for _ in range(steps):
        if field[i, j] == 0:
            break
        nxt = min(
            ((field[i + di, j + dj], i + di, j + dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj),
            key=lambda c: c[0],
        )
        if not nxt[0] < field[i, j]:
            break
        i, j = nxt[1], nxt[2]
        path.append(grid.centre(i, j))
    return path


def _walkable(grid: NavGrid, a, b, skip: float) -> bool:
    """The segment a→b stays in free cells, except within ``skip`` of a (where the player may already be)."""
    length = math.dist(a, b)
    n = max(1, int(length / 4))
    for k in range(n + 1):
        if k * length / n < skip:
            continue
        if not grid.is_free(a[0] + (b[0] - a[0]) * k / n, a[1] + (b[1] - a[1]) * k / n):
            return False
    return True


class HouseOracle:
    """Acts in a HouseEnv (unwrapped) from its privileged state."""

    def __init__(self, env: HouseEnv):
        self.env = env

    def _target(self) -> int:
        """The referent to head for: the nearer by path when a question has two."""
        env = self.env
        x, y = env.pose[0], env.pose[1]
        return min(env.targets, key=lambda i: distance_at(env._grid, env._fields[i], x, y))

    def sees(self, target: int) -> bool:
        """EQA: the referent is in plain view (near the view's centre, close, no wall between)."""
        env = self.env
        x, y, angle = env.pose
        tx, ty = env.positions[target]
        bearing = math.degrees(math.atan2(ty - y, tx - x))
        off = abs((bearing - angle + 180) % 360 - 180)
        return (
            off <= SEE_HALF_ANGLE
            and math.dist((x, y), (tx, ty)) <= SEE_DISTANCE
            and sight_grid(env.house).segment_free((x, y), (tx, ty))
        )

    def act(self) -> np.ndarray:
        env = self.env
        target = self._target()
        if env.task_id == 1 and self.sees(target):
            return np.array([ANSWER, env.answer_id])
        x, y, angle = env.pose
        grid, field = plan(env.house, target, env.cfg.reach_distance)
        path = _descend(grid, field, x, y, int(LOOKAHEAD / grid.cell))
        tx, ty = env.positions[target]
        wx, wy = tx, ty
        for k in range(len(path) - 1, -1, -1):  # the farthest point of the path reachable in a straight line
            if _walkable(grid, (x, y), path[k], skip=2 * grid.cell):
                wx, wy = path[k]
                if k == len(path) - 1 and field[grid.index(wx, wy)] == 0:
                    wx, wy = tx, ty  # the goal is in reach: head for the piece itself, not past its edge
                break
        else:
            if path:
                wx, wy = path[min(1, len(path) - 1)]
        want = math.degrees(math.atan2(wy - y, wx - x))
        error = (want - angle + 180) % 360 - 180  # >0: to the left (angles grow counter-clockwise)
        if abs(error) <= env.cfg.turn_degrees / 2:
            return np.array([FORWARD, 0])
        return np.array([LEFT if error > 0 else RIGHT, 0])
