"""The claims page's gate figure: the stated model's question gate over training, per seed (emml/report/eqa_test.py).

x_sent (Eq. 4) is read on the EQA test questions whose subject no training question names ('torch', 'blue'):
the gate's mass on the answer's attribute channels over its total (emml/eval/diagnose_gate.py), a panel per
attribute (colour questions, object questions), a line per seed of Table 2's Dual-Attention, Doom Easy, Aux,
labelled with the seed's EQA test. A run trained with the diagnostic has a point at every evaluation; a run filled
afterwards (`emml diagnose --gate --record`) one point, at its final checkpoint. Whether the gate opens the colour
channels on a colour question decided EQA test on the seeds read so far (docs/fidelity.md).
"""

from __future__ import annotations

from pathlib import Path

from emml.report.eqa_test import Arm

PANELS = (("diag/gate_on_color", "colour questions"), ("diag/gate_on_object", "object questions"))
"""The figure's panels: the gate figure drawn and the questions it is read on."""
HEIGHT = 2.6
"""Inches: the figure's height (its width the page's, `PAGE_INCHES`)."""


def has_points(stated: Arm) -> bool:
    """Whether any seed of the stated model has a gate figure to draw."""
    return any(g.history.get(key) for g in stated.gates.values() for key, _ in PANELS)


def figure(stated: Arm, paths: list[Path]) -> list[Path]:
    """The stated model's gate per seed over frames (`draw`), written to each of ``paths`` (PNG, PDF); nothing (and
    []) when no seed has a gate figure."""
    fig = draw(stated)
    if fig is None:
        return []
    import matplotlib.pyplot as plt

    from emml.report.savefig import save

    out = [save(fig, path) for path in paths]
    plt.close(fig)
    return out


def draw(stated: Arm):
    """The figure (a matplotlib Figure, not saved), or None when no seed has a gate figure."""
    if not has_points(stated):
        return None
    import matplotlib.pyplot as plt

    from emml.report.savefig import PAGE_INCHES, frames_axis

    fig, axes = plt.subplots(1, len(PANELS), figsize=(PAGE_INCHES, HEIGHT), sharey=True, layout="constrained")
    from matplotlib.ticker import MaxNLocator

    last = max(step for g in stated.gates.values() for key, _ in PANELS for step, _ in g.history.get(key, ()))
    ticks = [t for t in MaxNLocator(5).tick_values(0, last) if 0 <= t <= last]
    for ax, (key, title) in zip(axes, PANELS):
        # ticks up to the last point and half a tick of room after it: a tick at the axis' end would put half its
        # label outside the canvas
        ax.set_xticks(ticks)
        ax.set_xlim(0, last + (ticks[1] - ticks[0]) / 2 if len(ticks) > 1 else last * 1.1)
        for i, score in enumerate(stated.scores):
            gate = stated.gates.get(score.run)
            points = gate.history.get(key, ()) if gate is not None else ()
            if not points:
                continue
            steps, values = zip(*points)
            label = f"seed {score.seed} (EQA test {score.value:.2f})"
            ax.plot(steps, values, marker="o", ms=3, lw=1, color=f"C{i % 10}", label=label)
        ax.set_title(title)
        ax.set_ylim(-0.02, 1.02)  # a share, a point at 0 or 1 drawn whole
        frames_axis(ax)
    axes[0].set_ylabel("gate on the answer's attribute")
    axes[-1].legend(fontsize=6, loc="lower right")
    fig.suptitle("The stated model's question gate on unseen-subject test questions, per seed")
    return fig
