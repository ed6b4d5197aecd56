"""The House's example-views figure (Appendix C): three first-person views, each on which the oracle answers."""

import numpy as np
from PIL import Image

from emml.config.schema import HouseConfig
from emml.envs.house import HouseEnv
from emml.report.house_views import QUESTIONS, answer_view, house_views


def test_each_view_shows_its_referent_and_the_figure_is_written(tmp_path, no_leftovers):
    env = HouseEnv(HouseConfig(tasks="eqa", split="train", aux_labels=True), render_mode="rgb_array")
    try:
        for i, question in enumerate(QUESTIONS):
            frame, answer = answer_view(env, question, seed=i)
            assert frame.ndim == 3 and frame.shape[2] == 3 and answer in ("red", "green", "blue", "yellow")
            assert env._info(False)["target_mask"].any(), f"{question!r}: the referent is not in the view"
    finally:
        env.close()
    path = house_views(tmp_path / "house-views.png")
    with Image.open(path) as img:
        assert img.width > 3 * img.height and np.asarray(img).std() > 10  # three panels side by side, not blank
