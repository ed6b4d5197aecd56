"""Build the Doom room of the EMML tasks as a WAD file, from Python.

No ACS compiler exists on our machines, so the map is written as a UDMF ``TEXTMAP`` lump (namespace ``zdoom``);
the engine builds its nodes at load time. The WAD also carries a ``DECORATE`` lump with solid, non-pickup clones
of the keycards, skull keys and armors, so that every object stays where it was put (see ``objects.py``).

The room follows the reference SGN environment of Chaplot et al. (2018), which the EMML paper adapts:
x ∈ [0, 384], y ∈ [320, 704] (Doom map units). One map per player start angle (0°, 90°, 180°, 270°) lets a Hard
episode start facing any of the four directions: ``set_doom_map`` switches maps in about a millisecond.
"""

from __future__ import annotations

import hashlib
import os
import struct
import tempfile
from dataclasses import dataclass
from pathlib import Path

from emml.envs.objects import decorate_lump


@dataclass(frozen=True)
class Room:
    """Axis-aligned room geometry, in Doom map units."""

    x_min: int = 0
    """West wall."""
    x_max: int = 384
    """East wall."""
    y_min: int = 320
    """South wall."""
    y_max: int = 704
    """North wall."""
    ceiling: int = 128
    """Ceiling height (the floor is at 0)."""
    wall_texture: str = "STARTAN2"
    floor_texture: str = "FLOOR0_2"
    ceiling_texture: str = "CEIL3_5"
    light: int = 192
    """Sector light level (0..255); uniform, no dynamic lights."""


ROOM = Room()
"""The one room of the Doom tasks."""

START_ANGLES = (0, 90, 180, 270)
"""Player start angles, one map each: MAP01 faces east (0°), MAP02 north, MAP03 west, MAP04 south."""


def map_name(angle: int) -> str:
    """Name of the map whose player start faces ``angle`` degrees (one of START_ANGLES)."""
    return f"MAP{START_ANGLES.index(angle) + 1:02d}"


def textmap(room: Room, start: tuple[int, int], angle: int) -> str:
    """The UDMF text of one map: four walls, one sector, one player start."""
    corners = [  # clockwise, so that every linedef's front (right) side faces into the room
        (room.x_min, room.y_min),
        (room.x_min, room.y_max),
        (room.x_max, room.y_max),
        (room.x_max, room.y_min),
    ]
    flags = " ".join(f"skill{i} = true;" for i in range(1, 6))
    parts = ['namespace = "zdoom";']
    parts.append(
        f"thing {{ x = {start[0]:.1f}; y = {start[1]:.1f}; angle = {angle}; type = 1; {flags} "
        "single = true; coop = true; dm = true; class1 = true; class2 = true; class3 = true; }"
    )
    parts += [f"vertex {{ x = {x:.1f}; y = {y:.1f}; }}" for x, y in corners]
    for i in range(4):
        parts.append(f"linedef {{ v1 = {i}; v2 = {(i + 1) % 4}; sidefront = {i}; blocking = true; }}")
        parts.append(f'sidedef {{ sector = 0; texturemiddle = "{room.wall_texture}"; }}')
    parts.append(
        f'sector {{ heightfloor = 0; heightceiling = {room.ceiling}; texturefloor = "{room.floor_texture}"; '
        f'textureceiling = "{room.ceiling_texture}"; lightlevel = {room.light}; }}'
    )
    return "\n".join(parts) + "\n"


def pack_wad(lumps: list[tuple[str, bytes]]) -> bytes:
    """Pack named lumps into a PWAD (12-byte header, lump data, 16-byte directory entries)."""
    data = b"".join(body for _, body in lumps)
    header = struct.pack("<4sii", b"PWAD", len(lumps), 12 + len(data))
    directory, offset = b"", 12
    for name, body in lumps:
        directory += struct.pack("<ii8s", offset, len(body), name.encode("ascii"))
        offset += len(body)
    return header + data + directory


def build_wad(room: Room = ROOM, start: tuple[int, int] = (128, 512)) -> bytes:
    """The full WAD: one map per start angle, plus the DECORATE lump of solid object clones."""
    lumps: list[tuple[str, bytes]] = [("DECORATE", decorate_lump().encode("ascii"))]
    for angle in START_ANGLES:
        lumps += [(map_name(angle), b""), ("TEXTMAP", textmap(room, start, angle).encode("ascii")), ("ENDMAP", b"")]
    return pack_wad(lumps)


def wad_path(room: Room = ROOM, start: tuple[int, int] = (128, 512)) -> Path:
    """Write the WAD once per content into the temp dir (`write_once`)."""
    return write_once(build_wad(room, start), "emml-doom")


def write_once(blob: bytes, prefix: str) -> Path:
    """``blob`` as <tmp>/<prefix>-<sha1[:12]>.wad, written once per content: content-addressed, so concurrent
    writers agree, and atomic, so a reader never sees half a file."""
    path = Path(tempfile.gettempdir()) / f"{prefix}-{hashlib.sha1(blob).hexdigest()[:12]}.wad"
    if not path.exists():
        replace_with(path, blob)
    return path


def replace_with(path: Path, blob: bytes) -> None:
    """``path`` replaced by ``blob`` atomically (a reader never sees half a file), through a private temp name per
    writer (forked workers share id(blob), so a name built from it collides); the temp file removed on failure. The
    engines' temp-dir files' writer (emml/runs/atomic.py writes the project's own files)."""
    fd, tmp = tempfile.mkstemp(prefix=path.stem + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(blob)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
