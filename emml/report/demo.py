"""The report of `make demo`: the run's final greedy accuracies and its training curve."""

from __future__ import annotations

from pathlib import Path

from emml.config import TrainConfig
from emml.report.curves import plot_run
from emml.tracking import tracking_uri


def write_demo_report(cfg: TrainConfig, result, out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    name = cfg.run_name()
    png = plot_run(
        result.run_id,
        out / f"{name}.png",
        f"{cfg.model}, Doom {cfg.env.difficulty}, aux={cfg.aux}: profile {cfg.profile}, {result.frames:,} frames",
    )
    m = result.metrics
    lines = [
        f"# Demo run: {name}",
        "",
        f"Dual-Attention with the auxiliary task on Doom {cfg.env.difficulty.capitalize()}, profile "
        f"**{cfg.profile}** ({result.frames:,} frames, {cfg.num_envs} actors × {cfg.num_steps} steps per update, "
        f"input {cfg.env.height}×{cfg.env.width}). This is a short demonstration, not the paper's protocol "
        "(10M frames at 168×300): its numbers are not comparable with the paper's Table 2. At this budget the "
        "paper's learning rate moves the policy little; the committed quick-profile runs in `results/` and the "
        "suite's learning test (`tests/rl/test_trainer.py::test_learning_beats_chance`) show learning.",
        "",
        f"Greedy accuracy over {cfg.eval_episodes} episodes per cell:",
        "",
        "| task | train | test |",
        "|---|---|---|",
        f"| SGN | {m['sgn_train']:.2f} | {m['sgn_test']:.2f} |",
        f"| EQA | {m['eqa_train']:.2f} | {m['eqa_test']:.2f} |",
        "",
        f"![training curve]({png.name})",
        "",
        f"MLflow run `{result.run_id}` in `{tracking_uri()}` (browse: `make ui`); checkpoint in `{result.run_dir}`.",
        "",
    ]
    md = out / f"{name}.md"
    md.write_text("\n".join(lines))
    return [md, png]
