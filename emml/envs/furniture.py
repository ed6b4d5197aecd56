"""The furniture of the House domain (Appendix C, Table 8): 6 classes × 4 colours, drawn by this module.

SUNCG's 3-D models are no longer distributed, so every piece is a sprite that the project draws itself: a side
view of each class (refrigerator, office chair, fish tank, fireplace, bed, sofa) built from numpy rectangles,
ellipses and lines, in one of the four colours with shading for depth and neutral greys for the parts that have no
colour (handles, glass, mattress, casters). Each sprite is quantised to the IWAD's palette and written as a Doom
picture (column posts) between the WAD's sprite markers; a DECORATE actor per (class, colour) shows it. The actor's
class name is what the label buffer reports, so the colour is part of it ('HouseRedSofa').

Sprites are billboards, as every Doom thing: one rotation, always facing the player. One pixel is one map unit.
"""

from __future__ import annotations

import functools
import struct
from dataclasses import dataclass

import numpy as np

from emml.envs.objects import iwad_path

COLORS: dict[str, tuple[int, int, int]] = {
    "red": (200, 32, 32),
    "green": (40, 160, 48),
    "blue": (48, 72, 216),
    "yellow": (232, 208, 40),
}
"""The four colours of Table 8, as base RGB (shaded darker and lighter on each piece)."""

BLACK = (16, 16, 16)
DARK = (48, 48, 48)
GREY = (112, 112, 112)
LIGHT = (176, 176, 176)
WHITE = (228, 228, 224)
WOOD = (104, 68, 36)
GLASS = (168, 184, 184)
"""Neutral materials: never one of the four colour words."""


@dataclass(frozen=True)
class Furniture:
    """One furniture class: its sprite code, collision size and drawing."""

    object: str
    """The class word of Table 8."""
    code: str
    """Two letters of the sprite prefix ('F' + code + colour initial makes the 4-letter sprite name)."""
    radius: int
    """Collision half-width in map units (Doom things collide as axis-aligned squares of side 2·radius)."""
    width: int
    """Sprite width in pixels (= map units)."""
    height: int
    """Sprite height in pixels (= map units)."""


FURNITURE: dict[str, Furniture] = {
    f.object: f
    for f in [
        Furniture("refrigerator", "RF", 20, 40, 84),
        Furniture("office_chair", "OC", 16, 40, 60),
        Furniture("fish_tank", "FT", 28, 64, 64),
        Furniture("fireplace", "FP", 32, 80, 72),
        Furniture("bed", "BD", 40, 104, 52),
        Furniture("sofa", "SF", 36, 96, 48),
    ]
}
"""The 6 classes of Table 8, by class word."""

COLLISION_HEIGHT = 56
"""Every piece is this tall for collision (whatever its sprite): the player cannot step onto it (as the Doom
room's solid clones, emml/envs/objects.py)."""


def actor_name(obj: str, color: str) -> str:
    """The dataset's actor name (the key in tasks/house.toml): 'RedOfficeChair'."""
    return color.capitalize() + "".join(p.capitalize() for p in obj.split("_"))


def spawn_class(obj: str, color: str) -> str:
    """The DECORATE class the engine summons and the label buffer reports: 'HouseRedOfficeChair'."""
    return "House" + actor_name(obj, color)


def sprite_name(obj: str, color: str) -> str:
    """The 4-letter sprite prefix: 'F' + class code + colour initial ('FOCR')."""
    return "F" + FURNITURE[obj].code + color[0].upper()


CLASS_TO_ACTOR: dict[str, str] = {spawn_class(o, c): actor_name(o, c) for o in FURNITURE for c in COLORS}
"""Engine class name (as the label buffer reports it) → actor name of the house dataset."""


# --- drawing ----------------------------------------------------------------------------------------------------


class Canvas:
    """An RGB image with an opacity mask; shapes paint over what is below. Coordinates: x right, y down."""

    def __init__(self, width: int, height: int):
        self.rgb = np.zeros((height, width, 3), dtype=np.float32)
        self.mask = np.zeros((height, width), dtype=bool)
        self.yy, self.xx = np.mgrid[0:height, 0:width] + 0.5  # pixel centres

    def paint(self, where: np.ndarray, color) -> None:
        self.rgb[where] = np.clip(np.asarray(color, dtype=np.float32), 0, 255)
        self.mask |= where

    def rect(self, x0, y0, x1, y1, color, radius: float = 0.0) -> None:
        """Filled rectangle [x0, x1) × [y0, y1), corners rounded by ``radius``."""
        xx, yy = self.xx, self.yy
        inside = (xx >= x0) & (xx < x1) & (yy >= y0) & (yy < y1)
        if radius > 0:
            cx = np.clip(xx, x0 + radius, x1 - radius)
            cy = np.clip(yy, y0 + radius, y1 - radius)
            inside &= (xx - cx) ** 2 + (yy - cy) ** 2 <= radius**2
        self.paint(inside, color)

    def ellipse(self, cx, cy, rx, ry, color) -> None:
        self.paint(((self.xx - cx) / rx) ** 2 + ((self.yy - cy) / ry) ** 2 <= 1.0, color)

    def line(self, x0, y0, x1, y1, color, width: float = 2.0) -> None:
        """A segment of the given thickness."""
        p = np.stack([self.xx - x0, self.yy - y0], axis=-1)
        d = np.array([x1 - x0, y1 - y0], dtype=np.float32)
        t = np.clip((p @ d) / max(float(d @ d), 1e-9), 0.0, 1.0)
        dist = np.linalg.norm(p - t[..., None] * d, axis=-1)
        self.paint(dist <= width / 2, color)


def shade(color, k: float) -> tuple[float, float, float]:
    """The colour darkened (k < 1) or lightened (k > 1)."""
    return tuple(float(min(255.0, c * k)) for c in color)


def _refrigerator(cv: Canvas, c) -> None:
    cv.rect(4, 80, 9, 84, BLACK)  # feet
    cv.rect(31, 80, 36, 84, BLACK)
    cv.rect(2, 2, 38, 81, c, radius=4)  # body
    cv.rect(2, 4, 6, 79, shade(c, 1.2))  # lit left edge
    cv.rect(34, 4, 38, 79, shade(c, 0.65))  # shaded right edge
    cv.rect(2, 27, 38, 30, shade(c, 0.45))  # freezer door split
    cv.rect(29, 10, 32, 24, LIGHT)  # handles
    cv.rect(29, 35, 32, 58, LIGHT)


def _office_chair(cv: Canvas, c) -> None:
    for x in (5, 20, 35):  # star base and casters
        cv.line(20, 50, x, 55, DARK, 3)
        cv.ellipse(x, 57, 3, 3, BLACK)
    cv.rect(18, 38, 22, 52, GREY)  # gas lift
    cv.rect(18, 24, 22, 34, DARK)  # back support
    cv.rect(8, 0, 32, 27, c, radius=6)  # backrest
    cv.rect(11, 3, 29, 24, shade(c, 1.15), radius=4)
    cv.rect(2, 24, 6, 36, DARK)  # armrests
    cv.rect(34, 24, 38, 36, DARK)
    cv.rect(3, 31, 37, 40, shade(c, 0.85), radius=3)  # seat


def _fish_tank(cv: Canvas, c) -> None:
    cv.rect(4, 36, 60, 64, shade(c, 0.8))  # cabinet stand
    cv.rect(31, 39, 33, 62, shade(c, 0.45))  # its two doors
    cv.rect(25, 48, 28, 52, LIGHT)
    cv.rect(36, 48, 39, 52, LIGHT)
    cv.rect(2, 3, 62, 37, c)  # frame
    cv.rect(5, 7, 59, 34, GLASS)  # water
    cv.rect(5, 29, 59, 34, GREY)  # gravel
    for x in range(7, 58, 6):
        cv.rect(x, 30, x + 2, 32, LIGHT)
    for cx, cy, d in ((20, 15, 1), (42, 22, -1)):  # fish: body and tail
        cv.ellipse(cx, cy, 6, 3, DARK)
        cv.line(cx - 7 * d, cy - 3, cx - 7 * d, cy + 3, DARK, 2)
    for cx, cy in ((50, 10), (52, 15), (49, 19)):  # bubbles
        cv.ellipse(cx, cy, 1.5, 1.5, WHITE)
    cv.rect(0, 0, 64, 4, shade(c, 0.6))  # lid


def _fireplace(cv: Canvas, c) -> None:
    cv.rect(6, 8, 74, 72, c)  # surround
    for row, y in enumerate(range(8, 72, 8)):  # brick courses
        cv.rect(6, y, 74, y + 1, shade(c, 0.55))
        for x in range(6 + 8 * (row % 2), 74, 16):
            cv.rect(x, y, x + 1, y + 8, shade(c, 0.55))
    cv.rect(22, 36, 58, 68, BLACK)  # firebox, arched
    cv.ellipse(40, 36, 18, 14, BLACK)
    cv.line(26, 64, 54, 60, WOOD, 4)  # logs
    cv.line(28, 60, 52, 64, shade(WOOD, 0.8), 4)
    cv.rect(0, 0, 80, 8, shade(c, 1.2))  # mantel shelf
    cv.rect(0, 6, 80, 8, shade(c, 0.5))
    cv.rect(2, 68, 78, 72, DARK)  # hearth


def _bed(cv: Canvas, c) -> None:
    cv.rect(2, 42, 8, 52, WOOD)  # legs
    cv.rect(96, 42, 102, 52, WOOD)
    cv.rect(0, 0, 9, 46, shade(c, 0.7), radius=3)  # headboard
    cv.rect(95, 18, 104, 46, shade(c, 0.7), radius=2)  # footboard
    cv.rect(9, 38, 95, 44, shade(c, 0.5))  # frame rail
    cv.rect(9, 24, 95, 39, WHITE)  # mattress
    cv.ellipse(21, 22, 11, 6, WHITE)  # pillow
    cv.ellipse(21, 23, 10, 4, LIGHT)
    cv.rect(36, 19, 95, 38, c, radius=2)  # blanket
    cv.rect(36, 19, 41, 38, shade(c, 1.25))  # folded edge


def _sofa(cv: Canvas, c) -> None:
    cv.rect(8, 41, 12, 48, WOOD)  # legs
    cv.rect(84, 41, 88, 48, WOOD)
    cv.rect(8, 0, 88, 26, shade(c, 0.8), radius=6)  # backrest
    cv.rect(4, 32, 92, 42, shade(c, 0.65))  # base
    cv.rect(13, 22, 83, 35, c, radius=3)  # seat cushions
    for x in (36, 59):
        cv.rect(x, 22, x + 2, 35, shade(c, 0.55))
    cv.rect(0, 12, 15, 42, c, radius=5)  # armrests
    cv.rect(81, 12, 96, 42, c, radius=5)
    cv.rect(2, 13, 13, 17, shade(c, 1.25))
    cv.rect(83, 13, 94, 17, shade(c, 1.25))


_DRAW = {
    "refrigerator": _refrigerator,
    "office_chair": _office_chair,
    "fish_tank": _fish_tank,
    "fireplace": _fireplace,
    "bed": _bed,
    "sofa": _sofa,
}


def draw(obj: str, color: str) -> tuple[np.ndarray, np.ndarray]:
    """The sprite of one piece: uint8 RGB (h, w, 3) and its bool opacity mask (h, w)."""
    f = FURNITURE[obj]
    cv = Canvas(f.width, f.height)
    _DRAW[obj](cv, COLORS[color])
    return cv.rgb.round().astype(np.uint8), cv.mask


# --- the WAD's lumps --------------------------------------------------------------------------------------------


@functools.cache
def palette() -> np.ndarray:
    """uint8 (256, 3): the IWAD's first PLAYPAL palette, which every picture indexes."""
    blob = iwad_path().read_bytes()
    count, dir_offset = struct.unpack_from("<ii", blob, 4)
    for i in range(count):
        offset, _, name = struct.unpack_from("<ii8s", blob, dir_offset + 16 * i)
        if name.rstrip(b"\0") == b"PLAYPAL":
            return np.frombuffer(blob, dtype=np.uint8, count=768, offset=offset).reshape(256, 3).copy()
    raise FileNotFoundError(f"no PLAYPAL lump in {iwad_path()}")


def quantize(rgb: np.ndarray) -> np.ndarray:
    """uint8 (h, w): each pixel's nearest palette index (Euclidean in RGB), computed once per distinct colour."""
    pal = palette().astype(np.int32)
    colours, inverse = np.unique(rgb.reshape(-1, 3).astype(np.int32), axis=0, return_inverse=True)
    nearest = ((colours[:, None, :] - pal[None]) ** 2).sum(-1).argmin(-1).astype(np.uint8)
    return nearest[inverse.reshape(-1)].reshape(rgb.shape[:2])


def doom_picture(index: np.ndarray, mask: np.ndarray) -> bytes:
    """A Doom picture lump: header (width, height, left and top offsets: centred, standing on the floor), one
    offset per column, then per column its posts (top, length, pad, pixels, pad) and the 0xFF terminator."""
    h, w = index.shape
    if h > 254:
        raise ValueError(f"sprite height {h} does not fit one post per column (<= 254)")
    columns = []
    for x in range(w):
        col, y = bytearray(), 0
        while y < h:
            if not mask[y, x]:
                y += 1
                continue
            start = y
            while y < h and mask[y, x]:
                y += 1
            col += bytes([start, y - start, 0]) + index[start:y, x].tobytes() + b"\0"
        columns.append(bytes(col) + b"\xff")
    header = struct.pack("<hhhh", w, h, w // 2, h)
    offsets, at = [], 8 + 4 * w
    for col in columns:
        offsets.append(at)
        at += len(col)
    return header + struct.pack(f"<{w}I", *offsets) + b"".join(columns)


@functools.cache
def sprite_lumps() -> tuple[tuple[str, bytes], ...]:
    """(lump name, picture) of every (class, colour): frame A, rotation 0 ('FOCRA0')."""
    out = []
    for obj in FURNITURE:
        for color in COLORS:
            rgb, mask = draw(obj, color)
            out.append((sprite_name(obj, color) + "A0", doom_picture(quantize(rgb), mask)))
    return tuple(out)


def decorate_lump() -> str:
    """DECORATE source of the 24 furniture actors: solid, static, one sprite frame each."""
    out = []
    for obj, f in FURNITURE.items():
        for color in COLORS:
            out.append(
                f"actor {spawn_class(obj, color)}\n{{\n  Radius {f.radius}\n  Height {COLLISION_HEIGHT}\n  +SOLID\n"
                f"  States\n  {{\n  Spawn:\n    {sprite_name(obj, color)} A -1\n    Stop\n  }}\n}}\n"
            )
    return "\n".join(out)


@functools.cache
def sprite_areas() -> dict[str, int]:
    """Opaque pixel count of every actor's sprite, by actor name (the dataset's `area`; no house sentence
    compares sizes)."""
    return {actor_name(o, c): int(draw(o, c)[1].sum()) for o in FURNITURE for c in COLORS}
