"""The house map (emml/envs/house_wad.py): sectors, openings, textures, slots, and the WAD's lumps."""

import re
import struct

from emml.envs.furniture import FURNITURE, sprite_lumps
from emml.envs.house_wad import HOUSE, build_wad, textmap, wad_path
from emml.envs.objects import iwad_path


def _blocks(kind: str, text: str) -> list[str]:
    return re.findall(kind + r" \{([^}]*)\}", text)


def _lumps(blob: bytes) -> list[str]:
    count, offset = struct.unpack_from("<ii", blob, 4)
    return [struct.unpack_from("<ii8s", blob, offset + 16 * i)[2].rstrip(b"\0").decode() for i in range(count)]


def test_one_sector_per_room_and_doorway_with_distinct_room_textures():
    text = textmap()
    sectors = _blocks("sector", text)
    assert len(sectors) == len(HOUSE.rooms) + len(HOUSE.doors) == 7
    rooms = HOUSE.rooms
    for attr in ("wall_texture", "floor_texture", "ceiling_texture"):
        assert len({getattr(r, attr) for r in rooms}) == len(rooms), attr
    things = _blocks("thing", text)
    assert len(things) == 1 and "type = 1;" in things[0]
    x, y, angle = HOUSE.spawn
    assert f"x = {x:.1f}; y = {y:.1f}; angle = {angle};" in things[0]


def test_each_doorway_opens_into_two_rooms_and_every_sector_is_closed():
    text = textmap()
    lines, sides = _blocks("linedef", text), _blocks("sidedef", text)
    vertices = _blocks("vertex", text)
    two = [ln for ln in lines if "twosided = true" in ln]
    assert len(two) == 2 * len(HOUSE.doors)  # each doorway meets a room at each end
    assert all("blocking = true" in ln for ln in lines if "twosided" not in ln)
    # every sector's boundary is closed: each vertex has as many edges in as out, per sector
    degree: dict = {}
    for ln in lines:
        v = dict(re.findall(r"(\w+) = (\w+);", ln))
        a, b = int(v["v1"]), int(v["v2"])
        assert a < len(vertices) and b < len(vertices)
        for side, (p, q) in (("sidefront", (a, b)), ("sideback", (b, a))):
            if side in v:
                sector = int(re.search(r"sector = (\d+)", sides[int(v[side])]).group(1))
                degree[(sector, p)] = degree.get((sector, p), 0) + 1
                degree[(sector, q)] = degree.get((sector, q), 0) - 1
    assert all(d == 0 for d in degree.values())


def test_slots_stand_inside_their_rooms_clear_of_the_walls():
    rooms = {r.name: r for r in HOUSE.rooms}
    assert sorted(s.object for s in HOUSE.slots) == sorted([*FURNITURE, "sofa"])  # one of each, two sofas
    for s in HOUSE.slots:
        r, half = rooms[s.room], FURNITURE[s.object].radius
        assert r.x_min + half < s.x < r.x_max - half and r.y_min + half < s.y < r.y_max - half, s
        assert HOUSE.room_of(s.x, s.y) == s.room
    assert HOUSE.room_of(*HOUSE.spawn[:2]) == "kitchen"


def test_wad_has_decorate_sprites_and_the_map(tmp_path, monkeypatch):
    blob = build_wad()
    names = _lumps(blob)
    assert names[0] == "DECORATE" and names[-3:] == ["MAP01", "TEXTMAP", "ENDMAP"]
    sprites = names[names.index("S_START") + 1 : names.index("S_END")]
    assert len(sprites) == 24 and sprites == [n for n, _ in sprite_lumps()]
    iwad = set(_lumps(iwad_path().read_bytes()))
    assert not {n[:4] for n in sprites} & {n[:4] for n in iwad}  # our sprite names shadow none of the IWAD's
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    assert wad_path() == wad_path() and wad_path().read_bytes() == blob  # content-addressed, written once
