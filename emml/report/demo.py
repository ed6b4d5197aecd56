"""The report of `make demo`: the run's final greedy accuracies, its training curve, and the diagnostics of every
evaluation (emml/eval/diagnose.py), so that a newcomer sees both that the agent learns and why."""

from __future__ import annotations

from pathlib import Path

from emml.config.schema import TrainConfig
from emml.eval.diagnose import SCALARS
from emml.report.curves import plot_run
from emml.runs.atomic import write_text
from emml.runs.diskspace import RERUN
from emml.runs.naming import run_name
from emml.runs.portable import portable, portable_uri
from emml.runs.store import metric_history, tracking_uri

LABELS = {
    "attention_on_target": "attention on target",
    "attention_mass_on_target": "attention mass on target",
    "detector_ap": "detector AP",
    "actor_sensitivity": "actor sensitivity",
    "x_image_saturated": "x_I channels pinned",
    "x_image_spatial_std": "x_I spatial std",
}
"""The diagnostics table's column per figure of `SCALARS` (until issue 66 the header named the first four only, and
each row had two cells more than it)."""


def _diagnostics_table(run_id: str) -> list[str]:
    """One row per evaluation: frames, greedy SGN accuracy and the diag/* figures logged with it."""
    from emml.eval.metrics import BY_NAME

    sgn = [BY_NAME[m] for m in ("sgn_train", "sgn_test")]  # the SGN splits, as declared (emml/eval/metrics.py)
    keys = [*(m.key for m in sgn), *(f"diag/{k}" for k in SCALARS)]
    curves = {k: dict(metric_history(run_id, k)) for k in keys}
    steps = sorted(set().union(*(c.keys() for c in curves.values())))
    if not steps:
        return []
    head = ["frames", *(m.label for m in sgn), *(LABELS[k] for k in SCALARS)]  # one column per key (issue 66)
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    digits = {"diag/x_image_spatial_std": 3}  # a collapsed map's spread is below 0.01 (as `summary_line` prints it)
    for s in steps:
        cells = [f"{s:,}"] + [f"{curves[k][s]:.{digits.get(k, 2)}f}" if s in curves[k] else "—" for k in keys]
        rows.append("| " + " | ".join(cells) + " |")
    return rows


def write_demo_report(cfg: TrainConfig, result, out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    name = run_name(cfg)
    tasks = {"both": "SGN and EQA", "sgn": "SGN only", "eqa": "EQA only"}[cfg.env.tasks]
    png = plot_run(
        result.run_id,
        out / f"{name}.png",
        f"{cfg.model}, Doom {cfg.env.difficulty}, {tasks}, aux={cfg.aux}: profile {cfg.profile}, "
        f"{result.frames:,} frames",
    )
    m = result.metrics
    lines = [
        f"# Demo run: {name}",
        "",
        f"Dual-Attention with the auxiliary task on Doom {cfg.env.difficulty.capitalize()}, {tasks}, profile "
        f"**{cfg.profile}** ({result.frames:,} frames, {cfg.num_envs} actors × {cfg.num_steps} steps per update, "
        f"input {cfg.env.height}×{cfg.env.width}, the paper's learning rate and losses). A reduced setting, not the "
        "paper's protocol (both tasks, 10M frames at 168×300): its numbers are not comparable with the paper's "
        "Table 2. It shows the agent leaving chance (0.2: one object of five) on instruction following.",
        "",
        f"Greedy accuracy over {cfg.final_eval_episodes} episodes per cell:",
        "",
        "| task | train | test |",
        "|---|---|---|",
    ]
    for task in ("sgn", "eqa"):
        if f"{task}_train" in m:
            lines.append(f"| {task.upper()} | {m[f'{task}_train']:.2f} | {m.get(f'{task}_test', float('nan')):.2f} |")
    lines += ["", f"![training curve]({png.name})", ""]
    diag = _diagnostics_table(result.run_id)
    if diag:
        lines += [
            "What the agent looks at, at each evaluation (`emml diagnose`, docs/fidelity.md): how often the argmax "
            "of its spatial attention lies on the target, the attention mass there, the mean average precision of "
            "its word detectors against the aux labels, how much its first move depends on where the target "
            "stands (0: not at all), and whether x_I collapsed to a constant code (the share of conv3 channels "
            "pinned on every cell, x_I's spatial spread).",
            "",
            *diag,
            "",
        ]
    lines += [
        f"MLflow run `{result.run_id}` in `{portable_uri(tracking_uri())}` (browse: `make ui`); checkpoint in "
        f"`{portable(str(result.run_dir))}`.",
        "",
    ]
    md = out / f"{name}.md"
    write_text(md, "\n".join(lines), then=RERUN)
    return [md, png]
