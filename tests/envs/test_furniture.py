"""The furniture sprites the project draws (emml/envs/furniture.py): pictures, colours, actors."""

import struct

import numpy as np

from emml.envs.furniture import (
    CLASS_TO_ACTOR,
    COLORS,
    FURNITURE,
    decorate_lump,
    doom_picture,
    draw,
    palette,
    quantize,
    sprite_lumps,
)
from emml.tasks.language import load_dataset


def _decode(lump: bytes):
    """A Doom picture back to (index, mask)."""
    w, h, left, top = struct.unpack_from("<hhhh", lump, 0)
    index, mask = np.zeros((h, w), np.uint8), np.zeros((h, w), bool)
    for x, col in enumerate(struct.unpack_from(f"<{w}I", lump, 8)):
        p = col
        while lump[p] != 0xFF:
            top_delta, length = lump[p], lump[p + 1]
            index[top_delta : top_delta + length, x] = np.frombuffer(lump, np.uint8, length, p + 3)
            mask[top_delta : top_delta + length, x] = True
            p += length + 4
    return index, mask, (left, top)


def test_pictures_decode_to_the_drawing():
    for name, lump in sprite_lumps()[::5]:
        obj = next(o for o, f in FURNITURE.items() if f.code == name[1:3])
        color = next(c for c in COLORS if c[0].upper() == name[3])
        rgb, mask = draw(obj, color)
        index, got_mask, offsets = _decode(lump)
        assert np.array_equal(got_mask, mask) and np.array_equal(index[mask], quantize(rgb)[mask])
        assert offsets == (mask.shape[1] // 2, mask.shape[0])  # centred, standing on the floor
    assert (
        doom_picture(np.zeros((2, 1), np.uint8), np.array([[False], [False]]))
        == struct.pack("<hhhhI", 1, 2, 0, 2, 12) + b"\xff"
    )


def test_each_colour_shows_in_its_sprites():
    """Where the four variants of a class differ, the red one is mostly red, the blue one blue, and so on."""
    channel = {"red": [0], "green": [1], "blue": [2], "yellow": [0, 1]}
    for obj in FURNITURE:
        drawn = {c: draw(obj, c) for c in COLORS}
        shown = {c: palette()[quantize(rgb)].astype(float) for c, (rgb, _) in drawn.items()}
        differs = np.zeros(drawn["red"][1].shape, bool)
        for c in COLORS:
            differs |= np.any(shown[c] != shown["red"], axis=-1)
        assert differs.sum() > 0.3 * drawn["red"][1].sum(), obj  # the colour covers much of the piece
        for c, chans in channel.items():
            mean = shown[c][differs].mean(axis=0)
            others = [k for k in range(3) if k not in chans]
            assert min(mean[chans]) > 1.3 * max(mean[others]), (obj, c, mean)


def test_actors_match_the_dataset():
    ds = load_dataset("house")
    assert sorted(CLASS_TO_ACTOR.values()) == sorted(ds.actors)
    for cls, name in CLASS_TO_ACTOR.items():
        assert f"actor {cls}\n" in decorate_lump()
        assert cls == "House" + name
