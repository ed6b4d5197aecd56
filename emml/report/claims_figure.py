"""The claims page's figure (emml/report/claims_page.py): ours against the paper per claim, one line each, its
status in its label's colour. The page chooses the cells each claim shows and hands them over; this module owns how
they are drawn (colours, width) and imports nothing of the page."""

from __future__ import annotations

from emml.eval.metrics import TASKS, train_of
from emml.experiments.claims.evidence import (
    BUDGET,
    CLOSING,
    CONTRADICTED,
    INCONCLUSIVE,
    ONE_SEED,
    SUPPORTED,
    UNKNOWN_FLAT,
    UNTESTABLE,
)

STATUS_COLOURS = {
    SUPPORTED: "#1a7f37",
    CONTRADICTED: "#cf222e",
    ONE_SEED: "#9a6700",
    CLOSING: "#9a6700",
    UNKNOWN_FLAT: "#9a6700",
    INCONCLUSIVE: "#bc4c00",
    BUDGET: "#6e7781",
    UNTESTABLE: "#8c959f",
}
"""The figure's colour for each status (its tick label)."""
TASK_COLOURS = {**{task: train_of(task).colour for task in TASKS}, "diag": "C2"}
"""A claim's colour: its task's, as its training split's curve is drawn (emml/eval/metrics.py); a diag/* figure
C2."""
FIGURE_WIDTH = 7.0
"""Inches: the figure prints across a two-column page (or a one-column one) at its own size."""


def figure(decisions: list, shown: dict, curves: set, paths: list) -> None:
    """Ours against the paper per claim, one line each (its status in its label's colour): for each focus cell the
    paper's number (×), our mean (●) and each seed (○), joined by a line; FIGURE_WIDTH inches wide, written to each
    of ``paths`` (PNG, PDF). ``shown``: each claim's cells by its id (emml.report.claims_page.cells); ``curves``: the
    ids of the claims read on a curve, whose numbers are frames (noted, not drawn)."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from emml.report.savefig import save

    n = len(decisions)
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 0.8 + 0.22 * n), layout="constrained")
    for i, d in enumerate(decisions):
        y = n - 1 - i
        cs = [c for c in shown[d.id] if not c.frames]
        if not cs:
            note = "a curve's crossing in frames: see the table" if d.id in curves else "no number"
            ax.text(0.01, y, note, va="center", fontsize=6, color="0.45")
            continue
        step = min(0.6 / len(cs), 0.18)
        for j, c in enumerate(cs):
            yy = y + (len(cs) - 1) / 2 * step - j * step
            colour = TASK_COLOURS[c.task]
            mean = sum(c.ours) / len(c.ours) if c.ours else None
            if c.paper is not None and mean is not None:
                ax.plot([c.paper, mean], [yy, yy], color=colour, alpha=0.35, lw=1)
            if c.paper is not None:
                ax.plot(c.paper, yy, "x", color=colour, ms=4, mew=1)
            ax.plot(c.ours, [yy] * len(c.ours), "o", mfc="none", color=colour, ms=2.5, mew=0.6)
            if mean is not None:
                ax.plot(mean, yy, "o", color=colour, ms=3.5)
    ax.set_yticks(range(n), [f"{d.id}: {d.status} ({d.seeds or 0})" for d in reversed(decisions)])
    for label, d in zip(ax.get_yticklabels(), reversed(decisions)):
        label.set_color(STATUS_COLOURS.get(d.status, "black"))
    ax.set_ylim(-0.6, n - 0.4)
    ax.set_xlim(-0.02, 1.02)  # a point at 0 or 1 drawn whole
    ax.set_xlabel("success rate (a diag/* figure: its value)")
    ax.grid(axis="y", visible=False)
    handles = [
        Line2D([], [], ls="none", marker="x", color="0.2", label="paper"),
        Line2D([], [], ls="none", marker="o", color="0.2", label="ours (mean)"),
        Line2D([], [], ls="none", marker="o", mfc="none", color="0.2", label="ours (a seed)"),
        *(Line2D([], [], ls="none", marker="s", color=TASK_COLOURS[t], label=t.upper()) for t in TASKS),
        Line2D([], [], ls="none", marker="s", color=TASK_COLOURS["diag"], label="diag/*"),
    ]
    ax.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=6, fontsize=6)
    ax.set_title("Ours against the paper per claim (label: status, seeds)", pad=14)
    for path in paths:
        save(fig, path)
    plt.close(fig)
