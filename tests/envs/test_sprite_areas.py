"""The sprite areas the datasets carry as data (emml/tasks/*.toml `area`, compared by 'smallest'/'largest') are the
areas of the sprites the envs show: measured again from the IWAD (Doom) and from the drawn furniture (House)."""

import pytest

from emml.envs import furniture, objects
from emml.tasks.language import load_dataset


@pytest.mark.parametrize("dataset, measure", [("doom", objects.sprite_areas), ("house", furniture.sprite_areas)])
def test_dataset_areas_are_the_sprites_areas(dataset, measure):
    areas = {name: actor.area for name, actor in load_dataset(dataset).actors.items()}
    assert areas == measure()
