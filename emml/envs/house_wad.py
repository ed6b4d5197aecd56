"""The house of the House domain (Appendix C) as a WAD file, from Python: rooms, doorways, furniture slots.

The paper trains in one SUNCG house of House3D; SUNCG is no longer distributed, so this is our own fixed house:
four rooms in a 2×2 block (kitchen, study, living room, bedroom), each with its own wall, floor and ceiling
textures, separated by 16-unit walls and joined by three 96-unit doorways in a U (kitchen–study–living
room–bedroom; no door between bedroom and kitchen, so the path distance to the bedroom is much longer than the
straight line). Furniture stands at 7 fixed slots: one of each class and two sofas (the paper's example views show
two sofas of different colours at once).

Like the Doom room (emml/envs/wad.py), the map is a UDMF ``TEXTMAP`` (namespace ``zdoom``): every room and
doorway is a rectangular sector; a sector edge that another sector's edge runs along backwards becomes one
two-sided linedef, every other edge a one-sided blocking wall. Doorways have a lower ceiling (a lintel). The WAD
also carries the 24 furniture sprites and their DECORATE actors (emml/envs/furniture.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from emml.envs.furniture import decorate_lump, sprite_lumps
from emml.envs.wad import pack_wad, write_once


@dataclass(frozen=True)
class Area:
    """An axis-aligned rectangular sector (a room or a doorway), in map units."""

    name: str
    x_min: int
    y_min: int
    x_max: int
    y_max: int
    wall_texture: str
    """Texture of its one-sided walls (and of the lintel above a doorway, seen from this room)."""
    floor_texture: str
    ceiling_texture: str
    ceiling: int = 128
    """Ceiling height (every floor is at 0)."""
    light: int = 192
    """Sector light level (0..255)."""

    def corners(self) -> list[tuple[int, int]]:
        """Clockwise (x right, y up), so that each edge's right side, a linedef's front, faces inside."""
        return [(self.x_min, self.y_min), (self.x_min, self.y_max), (self.x_max, self.y_max), (self.x_max, self.y_min)]

    def contains(self, x: float, y: float) -> bool:
        return self.x_min <= x <= self.x_max and self.y_min <= y <= self.y_max


@dataclass(frozen=True)
class Slot:
    """A fixed furniture spot: which class stands there (its colour is drawn per episode)."""

    object: str
    """Class word of Table 8."""
    x: int
    y: int
    room: str


@dataclass(frozen=True)
class House:
    """The whole fixed scene: sectors, furniture slots and the agent's spawn pose."""

    rooms: tuple[Area, ...]
    doors: tuple[Area, ...]
    slots: tuple[Slot, ...]
    spawn: tuple[int, int, int]
    """(x, y, angle°) of the agent at every episode start (Appendix C: 'The agent's spawn location is fixed')."""

    @property
    def areas(self) -> tuple[Area, ...]:
        return self.rooms + self.doors

    @property
    def bounds(self) -> tuple[int, int, int, int]:
        """(x_min, y_min, x_max, y_max) of everything."""
        a = self.areas
        return min(r.x_min for r in a), min(r.y_min for r in a), max(r.x_max for r in a), max(r.y_max for r in a)

    def room_of(self, x: float, y: float) -> str | None:
        for r in self.rooms:
            if r.contains(x, y):
                return r.name
        return None


def _door(name: str, x_min: int, y_min: int, x_max: int, y_max: int) -> Area:
    return Area(name, x_min, y_min, x_max, y_max, "WOODVERT", "FLAT5_5", "CEIL5_1", ceiling=112, light=176)


HOUSE = House(
    rooms=(  # 448 × 448 each, 16-unit walls between them
        Area("kitchen", 0, 0, 448, 448, "STARTAN3", "FLOOR0_1", "CEIL3_5", light=208),
        Area("study", 464, 0, 912, 448, "PANBOOK", "FLOOR4_8", "CEIL1_1", light=176),
        Area("living_room", 464, 464, 912, 912, "WOOD1", "FLAT5_5", "CEIL3_3", light=192),
        Area("bedroom", 0, 464, 448, 912, "GRAY5", "FLAT5_1", "CEIL5_2", light=184),
    ),
    doors=(
        _door("kitchen-study", 448, 176, 464, 272),
        _door("study-living_room", 640, 448, 736, 464),
        _door("living_room-bedroom", 448, 640, 464, 736),
    ),
    slots=(
        Slot("refrigerator", 352, 420, "kitchen"),
        Slot("office_chair", 816, 288, "study"),
        Slot("fish_tank", 600, 40, "study"),
        Slot("fireplace", 688, 872, "living_room"),
        Slot("sofa", 864, 672, "living_room"),
        Slot("sofa", 576, 836, "living_room"),
        Slot("bed", 160, 864, "bedroom"),
    ),
    spawn=(224, 224, 0),
)
"""The one house of the House domain."""

MAP = "MAP01"


def _split_edges(polygon: list[tuple[int, int]], points: set[tuple[int, int]]) -> list[tuple[tuple, tuple]]:
    """The polygon's directed edges, each cut at every point of ``points`` lying strictly inside it."""
    out = []
    for a, b in zip(polygon, polygon[1:] + polygon[:1]):
        inner = [
            p
            for p in points
            if p not in (a, b)
            and (p[0] - a[0]) * (b[1] - a[1]) == (p[1] - a[1]) * (b[0] - a[0])  # collinear
            and min(a[0], b[0]) <= p[0] <= max(a[0], b[0])
            and min(a[1], b[1]) <= p[1] <= max(a[1], b[1])
        ]
        inner.sort(key=lambda p: abs(p[0] - a[0]) + abs(p[1] - a[1]))
        chain = [a, *inner, b]
        out += list(zip(chain, chain[1:]))
    return out


def textmap(house: House = HOUSE) -> str:
    """The UDMF text of the house: one sector per area, walls and two-sided openings, one player start."""
    areas = house.areas
    points = {c for a in areas for c in a.corners()}
    edges = {i: _split_edges(a.corners(), points) for i, a in enumerate(areas)}
    owner = {e: i for i, es in edges.items() for e in es}  # directed edge → the sector on its right
    vertices: dict[tuple[int, int], int] = {}

    def vid(p):
        return vertices.setdefault(p, len(vertices))

    x, y, angle = house.spawn
    flags = " ".join(f"skill{i} = true;" for i in range(1, 6))
    parts = ['namespace = "zdoom";']
    parts.append(
        f"thing {{ x = {x:.1f}; y = {y:.1f}; angle = {angle}; type = 1; {flags} "
        "single = true; coop = true; dm = true; class1 = true; class2 = true; class3 = true; }"
    )
    lines, sides = [], []
    for i, es in edges.items():
        for a, b in es:
            j = owner.get((b, a))
            if j is not None and j < i:
                continue  # the two-sided line was written from the other sector
            front = len(sides)
            if j is None:
                sides.append(f'sidedef {{ sector = {i}; texturemiddle = "{areas[i].wall_texture}"; }}')
                lines.append(f"linedef {{ v1 = {vid(a)}; v2 = {vid(b)}; sidefront = {front}; blocking = true; }}")
            else:  # an opening: the lower-ceiling side shows nothing, the other the lintel in its own texture
                for k in (i, j):
                    sides.append(f'sidedef {{ sector = {k}; texturetop = "{areas[k].wall_texture}"; }}')
                lines.append(
                    f"linedef {{ v1 = {vid(a)}; v2 = {vid(b)}; sidefront = {front}; sideback = {front + 1}; "
                    "twosided = true; }"
                )
    parts += [
        f"vertex {{ x = {px:.1f}; y = {py:.1f}; }}" for (px, py), _ in sorted(vertices.items(), key=lambda v: v[1])
    ]
    parts += lines + sides
    for a in areas:
        parts.append(
            f'sector {{ heightfloor = 0; heightceiling = {a.ceiling}; texturefloor = "{a.floor_texture}"; '
            f'textureceiling = "{a.ceiling_texture}"; lightlevel = {a.light}; }}'
        )
    return "\n".join(parts) + "\n"


def build_wad(house: House = HOUSE) -> bytes:
    """The full WAD: DECORATE of the furniture actors, their sprites between the sprite markers, the map."""
    lumps: list[tuple[str, bytes]] = [("DECORATE", decorate_lump().encode("ascii")), ("S_START", b"")]
    lumps += list(sprite_lumps())
    lumps += [("S_END", b""), (MAP, b""), ("TEXTMAP", textmap(house).encode("ascii")), ("ENDMAP", b"")]
    return pack_wad(lumps)


def wad_path(house: House = HOUSE) -> Path:
    """Write the WAD once per content into the temp dir (emml.envs.wad.write_once)."""
    return write_once(build_wad(house), "emml-house")
