"""Path distances through the doorways (emml/envs/navigation.py) and the reachability of every piece."""

import math

import numpy as np

from emml.agents.house_oracle import plan
from emml.envs.house_wad import HOUSE
from emml.envs.navigation import distance_at, distance_field, nav_grid, point_goal, shaping_fields, shaping_grid

SPAWN = HOUSE.spawn[:2]


def test_every_piece_is_reachable_from_the_spawn():
    grid, fields = shaping_grid(HOUSE), shaping_fields(HOUSE)
    for slot, field in zip(HOUSE.slots, fields):
        assert math.isfinite(distance_at(grid, field, *SPAWN)), slot
    for i, slot in enumerate(HOUSE.slots):  # also with the oracle's margins and the other pieces in the way
        g, f = plan(HOUSE, i, 8.0)
        assert math.isfinite(distance_at(g, f, *SPAWN)), slot


def test_path_distance_goes_round_the_walls():
    grid, fields = shaping_grid(HOUSE), shaping_fields(HOUSE)
    by_object = {s.object: (s, f) for s, f in zip(HOUSE.slots, fields)}
    bed, field = by_object["bed"]  # the bedroom has no door to the kitchen: kitchen, study, living room, bedroom
    straight = math.dist(SPAWN, (bed.x, bed.y))
    assert distance_at(grid, field, *SPAWN) > 1.8 * straight
    fridge, field = by_object["refrigerator"]  # same room: the straight line, give or take the grid's 8 %
    straight = math.dist(SPAWN, (fridge.x, fridge.y))
    assert straight <= distance_at(grid, field, *SPAWN) <= 1.09 * straight
    # either side of the kitchen-bedroom wall: 32 units apart in a straight line, hundreds by the doorways
    f = distance_field(grid, point_goal(grid, 224, 424))
    assert distance_at(grid, f, 224, 488) > 900


def test_walls_block_and_doorways_pass():
    grid = shaping_grid(HOUSE)
    assert not grid.is_free(456, 100) and grid.is_free(456, 224)  # kitchen-study wall, then its doorway
    assert not grid.is_free(10, 10)  # the player's box does not fit in a corner
    blocked = nav_grid(HOUSE, 16, blockers=[(456, 224, 40)])
    f = distance_field(blocked, point_goal(blocked, 688, 224))
    assert not np.isfinite(distance_at(blocked, f, *SPAWN))  # a blocked doorway cuts the study off
