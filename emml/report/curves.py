"""Training curves from MLflow metric histories: training success per task vs frames (like the paper's Figures
7 and 8), with the greedy evaluation points."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from emml.tracking import metric_history  # noqa: E402

SERIES = (
    ("train/success_sgn", "SGN, training episodes", "C0", "-"),
    ("train/success_eqa", "EQA, training episodes", "C1", "-"),
    ("eval/sgn_train", "SGN train, greedy eval", "C0", "o"),
    ("eval/eqa_train", "EQA train, greedy eval", "C1", "o"),
    ("eval/sgn_test", "SGN test, greedy eval", "C2", "s"),
    ("eval/eqa_test", "EQA test, greedy eval", "C3", "s"),
)


def plot_run(run_id: str, path: Path, title: str) -> Path:
    fig, ax = plt.subplots(figsize=(7, 4))
    for key, label, color, style in SERIES:
        hist = metric_history(run_id, key)
        if not hist:
            continue
        steps, values = zip(*hist)
        if style == "-":
            ax.plot(steps, values, style, color=color, label=label)
        else:
            ax.plot(steps, values, style, color=color, label=label, linestyle="--", alpha=0.8)
    ax.axhline(0.2, color="grey", lw=0.8, ls=":", label="SGN chance (1 of 5)")
    ax.set_xlabel("frames (agent steps)")
    ax.set_ylabel("accuracy")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, loc="upper left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
