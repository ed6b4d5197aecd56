"""The actor catalogue: which engine class shows each of the 18 Doom objects, and how big its sprite is.

Torches and columns are solid decorations already. Keycards, skull keys and armors are pickups that vanish when
touched, so the WAD defines solid clones of them (``Solid*`` classes) that show the same sprites and stay put.
"""

from __future__ import annotations

import functools
import struct
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Actor:
    """How one object of the dataset exists in the engine."""

    name: str
    """The reference actor name (the key in tasks/doom.toml)."""
    spawn_class: str
    """The engine class that is summoned (a solid clone for pickups)."""
    sprite: str
    """Sprite prefix (4 letters); frame A is used to measure the area."""
    radius: int
    """Collision radius in map units (the engine's value for the original class)."""


def _actor(name: str, sprite: str, radius: int, clone: bool) -> Actor:
    return Actor(name, f"Solid{name}" if clone else name, sprite, radius)


ACTORS: dict[str, Actor] = {
    a.name: a
    for a in [
        _actor("ShortBlueTorch", "SMBT", 16, False),
        _actor("BlueTorch", "TBLU", 16, False),
        _actor("ShortRedTorch", "SMRT", 16, False),
        _actor("RedTorch", "TRED", 16, False),
        _actor("ShortGreenTorch", "SMGT", 16, False),
        _actor("GreenTorch", "TGRN", 16, False),
        _actor("ShortRedColumn", "COL4", 16, False),
        _actor("TallRedColumn", "COL3", 16, False),
        _actor("ShortGreenColumn", "COL2", 16, False),
        _actor("TallGreenColumn", "COL1", 16, False),
        _actor("YellowCard", "YKEY", 20, True),
        _actor("BlueCard", "BKEY", 20, True),
        _actor("RedCard", "RKEY", 20, True),
        _actor("YellowSkull", "YSKU", 20, True),
        _actor("BlueSkull", "BSKU", 20, True),
        _actor("RedSkull", "RSKU", 20, True),
        _actor("GreenArmor", "ARM1", 20, True),
        _actor("BlueArmor", "ARM2", 20, True),
    ]
}
"""The 18 objects of the Doom tasks (Appendix B, Figure 10), by reference name."""

CLASS_TO_ACTOR = {a.spawn_class: a.name for a in ACTORS.values()}
"""Engine class name (as the label buffer reports it) → reference actor name."""


def decorate_lump() -> str:
    """DECORATE source of the solid clones: same sprites and blinking, no pickup, tall enough not to be climbed."""
    out = []
    for a in ACTORS.values():
        if a.spawn_class != a.name:
            out.append(
                f"actor {a.spawn_class}\n{{\n  Radius {a.radius}\n  Height 56\n  +SOLID\n"
                f"  States\n  {{\n  Spawn:\n    {a.sprite} A 10\n    {a.sprite} B 10 Bright\n    Loop\n  }}\n}}\n"
            )
    return "\n".join(out)


def iwad_path() -> Path:
    """The IWAD ViZDoom ships (Freedoom 2), whose sprites and textures the tasks use."""
    import vizdoom

    return Path(vizdoom.__file__).parent / "freedoom2.wad"


@functools.cache
def sprite_areas(wad: Path | None = None) -> dict[str, int]:
    """Opaque pixel count of frame A (rotation 0) of every actor's sprite, read from the IWAD.

    This is the size measure behind 'smallest' and 'largest' (the reference environment compared sprite areas).
    A Doom picture is a header (width, height, offsets) and one column of posts per x; each post has a length.
    """
    blob = (wad or iwad_path()).read_bytes()
    count, dir_offset = struct.unpack_from("<ii", blob, 4)
    lumps = {}
    for i in range(count):
        offset, size, name = struct.unpack_from("<ii8s", blob, dir_offset + 16 * i)
        lumps.setdefault(name.rstrip(b"\0").decode("ascii"), (offset, size))
    areas = {}
    for a in ACTORS.values():
        offset, _ = lumps[f"{a.sprite}A0"]
        width = struct.unpack_from("<h", blob, offset)[0]
        column_offsets = struct.unpack_from(f"<{width}I", blob, offset + 8)
        pixels = 0
        for col in column_offsets:
            p = offset + col
            while blob[p] != 0xFF:  # posts until the 0xFF terminator: topdelta, length, pad, data, pad
                pixels += blob[p + 1]
                p += blob[p + 1] + 4
        areas[a.name] = pixels
    return areas
