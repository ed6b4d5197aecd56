"""The House's example first-person views (the paper's Appendix C figure `fig:house3d-objects`: "Example
first-person views of the House3D environment with sample objects of various colors"), from our ViZDoom House.

Each view is the frame on which the path-planning oracle (emml/agents/house_oracle.py) answers a question: the
referent is then in plain view, in the colour drawn for that episode. Different questions put different rooms and
furniture in the picture.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from emml.agents.house_oracle import HouseOracle  # noqa: E402
from emml.config.schema import HouseConfig  # noqa: E402
from emml.envs.doom import ANSWER  # noqa: E402
from emml.envs.house import HouseEnv  # noqa: E402
from emml.report.savefig import PAGE_INCHES, save, wrap  # noqa: E402

QUESTIONS = ("what color is the fireplace", "what color is the bed", "what color is the office_chair")
"""One training question per view (Table 8), each about a piece in a different room."""


def answer_view(env: HouseEnv, question: str, seed: int) -> tuple[np.ndarray, str]:
    """The rendered frame on which the oracle answers ``question`` (episode seeded by ``seed``), and its answer."""
    env.reset(seed=seed, options={"sentence": question})
    oracle = HouseOracle(env)
    for _ in range(env.cfg.max_steps):
        action = oracle.act()
        if int(action[0]) == ANSWER:
            return env.render(), env.episode.answer
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    raise RuntimeError(f"the oracle did not answer {question!r} (seed {seed})")


def house_views(path: Path, seed: int = 0, questions: tuple[str, ...] = QUESTIONS) -> Path:
    """Write the figure, a page's text wide (`PAGE_INCHES`): one panel per question, its view captioned with the
    question and the answer."""
    env = HouseEnv(HouseConfig(tasks="eqa", split="train"), render_mode="rgb_array")
    try:
        views = [answer_view(env, q, seed + i) for i, q in enumerate(questions)]
    finally:
        env.close()
    h, w = views[0][0].shape[:2]
    panel = PAGE_INCHES / len(views)  # a view's width: the page's text width shared
    fig, axes = plt.subplots(1, len(views), figsize=(PAGE_INCHES, panel * h / w + 0.8), layout="constrained")
    for ax, q, (frame, answer) in zip(np.atleast_1d(axes), questions, views):
        ax.imshow(frame)
        ax.set_title(wrap(f"{q}? {answer}", panel - 0.1, plt.rcParams["axes.titlesize"]))
        ax.axis("off")
    title = "Example first-person views of the House (emml/House-v0; colours drawn per episode)"
    fig.suptitle(wrap(title, PAGE_INCHES - 0.1, plt.rcParams["figure.titlesize"]))
    save(fig, path, dpi=150)
    plt.close(fig)
    return path
