"""Path distances in the house (Appendix C's distance shaping, measured through the doorways, not through walls).

The house is rasterised into 8-unit cells; a cell is free when a square of the given clearance around its centre
(the player's collision box: Doom things collide as axis-aligned squares) lies inside the rooms and doorways, and
outside any blocker square. Shortest paths run over the 8-connected free cells (diagonal steps only where both
side cells are free, so no path cuts a wall corner); Dijkstra gives a distance field from a goal to every cell.
The distance at a continuous point is the best neighbouring cell's value plus the straight step to its centre.

The env's shaping uses the walls only (the player's own clearance); the oracle plans with a wider clearance and
with the other furniture as blockers (touching any furniture ends an SGN episode).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from emml.envs.house_wad import House

CELL = 8
"""Grid cell side, map units."""
PLAYER_RADIUS = 16
"""Half-side of the player's collision box, map units."""


@dataclass(frozen=True, eq=False)
class NavGrid:
    """Free cells of the house at one clearance; cell (i, j) is centred at (x0 + (j + ½)·cell, y0 + (i + ½)·cell)."""

    x0: float
    y0: float
    cell: float
    free: np.ndarray
    """bool (rows = y, cols = x)."""

    def index(self, x: float, y: float) -> tuple[int, int]:
        return int(math.floor((y - self.y0) / self.cell)), int(math.floor((x - self.x0) / self.cell))

    def centre(self, i: int, j: int) -> tuple[float, float]:
        return self.x0 + (j + 0.5) * self.cell, self.y0 + (i + 0.5) * self.cell

    def inside(self, i: int, j: int) -> bool:
        return 0 <= i < self.free.shape[0] and 0 <= j < self.free.shape[1]

    def is_free(self, x: float, y: float) -> bool:
        i, j = self.index(x, y)
        return self.inside(i, j) and bool(self.free[i, j])

    def segment_free(self, a, b, step: float = 4.0) -> bool:
        """Every point of the segment a→b (sampled every ``step`` units) lies in a free cell."""
        n = max(1, int(math.dist(a, b) / step))
        return all(self.is_free(a[0] + (b[0] - a[0]) * k / n, a[1] + (b[1] - a[1]) * k / n) for k in range(n + 1))

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) of every cell centre, arrays shaped like ``free``."""
        rows, cols = self.free.shape
        ys, xs = np.mgrid[0:rows, 0:cols]
        return self.x0 + (xs + 0.5) * self.cell, self.y0 + (ys + 0.5) * self.cell


def nav_grid(house: House, clearance: float, blockers=(), cell: float = CELL) -> NavGrid:
    """Free cells: a square of half-side ``clearance`` around the centre fits in the rooms and doorways, and the
    centre lies outside every blocker square ``(x, y, half_side)``."""
    x_min, y_min, x_max, y_max = house.bounds
    pad = cell * 2
    x0, y0 = x_min - pad, y_min - pad
    cols, rows = int(math.ceil((x_max - x0 + pad) / cell)), int(math.ceil((y_max - y0 + pad) / cell))
    grid = NavGrid(x0, y0, cell, np.zeros((rows, cols), dtype=bool))
    xs, ys = grid.centres()
    inside = np.zeros((rows, cols), dtype=bool)
    for a in house.areas:
        inside |= (xs > a.x_min) & (xs < a.x_max) & (ys > a.y_min) & (ys < a.y_max)
    k = int(math.ceil(clearance / cell))
    free = ndimage.binary_erosion(inside, structure=np.ones((2 * k + 1, 2 * k + 1), dtype=bool), border_value=0)
    for bx, by, half in blockers:
        free &= np.maximum(np.abs(xs - bx), np.abs(ys - by)) > half
    return NavGrid(x0, y0, cell, free)


def _graph(grid: NavGrid):
    """The 8-connected graph of free cells (sparse, symmetric), without corner cutting. The grid's border cells
    are never free (nav_grid pads the house), so every neighbour of an inner cell exists."""
    free = grid.free
    rows, cols = free.shape
    assert not (free[0].any() or free[-1].any() or free[:, 0].any() or free[:, -1].any())
    ids = np.arange(rows * cols).reshape(rows, cols)[1:-1, 1:-1]

    def shifted(di: int, dj: int) -> np.ndarray:
        return free[1 + di : rows - 1 + di, 1 + dj : cols - 1 + dj]

    src, dst, w = [], [], []
    for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
        ok = shifted(0, 0) & shifted(di, dj)
        if di and dj:  # a diagonal step needs both side cells free
            ok &= shifted(di, 0) & shifted(0, dj)
        a = ids[ok]
        src.append(a)
        dst.append(a + di * cols + dj)
        w.append(np.full(a.shape, grid.cell * math.hypot(di, dj)))
    src, dst, w = np.concatenate(src), np.concatenate(dst), np.concatenate(w)
    return coo_matrix((w, (src, dst)), shape=(rows * cols, rows * cols)).tocsr()


def distance_field(grid: NavGrid, goal: np.ndarray) -> np.ndarray:
    """float (rows, cols): path length from every cell to the nearest goal cell (bool mask), inf if unreachable."""
    sources = np.flatnonzero(goal & grid.free)
    if sources.size == 0:
        raise ValueError("the goal covers no free cell")
    d = dijkstra(_graph(grid), directed=False, indices=sources, min_only=True)
    return d.reshape(grid.free.shape)


def distance_at(grid: NavGrid, field: np.ndarray, x: float, y: float) -> float:
    """Path distance from the point (x, y): min over nearby cells of (their distance + the step to their centre).
    Searches a wider ring when the point's own neighbourhood is blocked (the player drifted into a margin)."""
    i0, j0 = grid.index(x, y)
    for r in (1, 3, 6):
        best = math.inf
        for i in range(i0 - r, i0 + r + 1):
            for j in range(j0 - r, j0 + r + 1):
                if grid.inside(i, j) and math.isfinite(field[i, j]):
                    cx, cy = grid.centre(i, j)
                    best = min(best, field[i, j] + math.hypot(x - cx, y - cy))
        if math.isfinite(best):
            return best
    return math.inf


def point_goal(grid: NavGrid, x: float, y: float) -> np.ndarray:
    """The goal mask of one point: its cell."""
    goal = np.zeros(grid.free.shape, dtype=bool)
    goal[grid.index(x, y)] = True
    return goal


@functools.cache
def shaping_fields(house: House) -> tuple[np.ndarray, ...]:
    """Per furniture slot: the walls-only path distance field to its centre (the env's shaping, Appendix C)."""
    grid = shaping_grid(house)
    return tuple(distance_field(grid, point_goal(grid, s.x, s.y)) for s in house.slots)


@functools.cache
def shaping_grid(house: House) -> NavGrid:
    """The grid of the player's own free space: its box clear of the walls (furniture ignored)."""
    return nav_grid(house, PLAYER_RADIUS)
