"""`emml oracle --video`: the scripted expert acting in Easy and Hard episodes, recorded as a captioned GIF plus
a short Markdown summary."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from emml.agents.oracle import Oracle
from emml.config.schema import DoomConfig
from emml.envs.doom import DoomEnv
from emml.runs.atomic import replacing, write_text
from emml.runs.diskspace import RERUN

CAPTION_HEIGHT = 22


def _captioned(frame: np.ndarray, text: str) -> Image.Image:
    img = Image.new("RGB", (frame.shape[1], frame.shape[0] + CAPTION_HEIGHT), "black")
    img.paste(Image.fromarray(frame), (0, CAPTION_HEIGHT))
    ImageDraw.Draw(img).text((4, 5), text, fill="white")
    return img


def oracle_demo(out: Path, episodes: int = 3, seed: int = 0) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    frames: list[Image.Image] = []
    rows = []
    for difficulty in DoomConfig.DIFFICULTIES:
        for task in ("sgn", "eqa"):
            env = DoomEnv(DoomConfig(difficulty=difficulty, tasks=task), render_mode="rgb_array")
            agent = Oracle(env)
            try:
                for i in range(episodes):
                    env.reset(seed=seed + i)
                    text = env.episode.sentence.text
                    frames.append(_captioned(env.render(), f"{difficulty} {task}: {text}"))
                    for _ in range(env.cfg.max_steps):
                        action = agent.act()
                        _, _, terminated, truncated, info = env.step(action)
                        suffix = f" -> {env.episode.answer}" if task == "eqa" else ""
                        frames.append(_captioned(env.render(), f"{difficulty} {task}: {text}{suffix}"))
                        if terminated or truncated:
                            break
                    frames += [frames[-1]] * 4  # hold the last frame
                    rows.append((difficulty, task, text, info["success"], env.t))
            finally:
                env.close()
    gif = out / "oracle-demo.gif"
    with replacing(gif, then=RERUN) as tmp:
        frames[0].save(tmp, format="GIF", save_all=True, append_images=frames[1:], duration=120, loop=0)
    md = out / "oracle-demo.md"
    lines = [
        "# Scripted expert on the Doom tasks",
        "",
        "The oracle uses privileged state (object and agent poses). Recording: `oracle-demo.gif`.",
        "",
        "| difficulty | task | sentence | success | steps |",
        "|---|---|---|---|---|",
    ]
    lines += [f"| {d} | {t} | {s} | {ok} | {n} |" for d, t, s, ok, n in rows]
    write_text(md, "\n".join(lines) + "\n", then=RERUN)
    return [gif, md]
