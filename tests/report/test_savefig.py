"""What every figure shares: its print widths, the frames axis, and the check that no text leaves the canvas."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from emml.report.savefig import COLUMN_INCHES, frames_axis, outside, wrap  # noqa: E402


def test_outside_names_the_texts_the_canvas_cuts_and_only_those():
    fig, ax = plt.subplots(figsize=(COLUMN_INCHES, 2), layout="constrained")
    ax.plot([0, 2e6], [0, 1])
    ax.set_title("fits")
    frames_axis(ax)
    assert outside(fig) == []
    ax.set_title("a title much too long for a figure one column wide, cut at both of its edges")
    fig.text(0.99, 0.5, "past the right edge")
    assert outside(fig) == [
        "a title much too long for a figure one column wide, cut at both of its edges",
        "past the right edge",
    ]
    ax.set_title(wrap("a title much too long for a figure one column wide, cut at both of its edges", 3.2, 8))
    fig.texts.clear()
    assert outside(fig) == []
    plt.close(fig)


def test_the_frames_axis_reads_millions():
    fig, ax = plt.subplots()
    ax.plot([0, 5e6], [0, 1])
    frames_axis(ax)
    fig.canvas.draw()
    assert [t.get_text() for t in ax.get_xticklabels()][1:4] == ["0", "1", "2"]
    assert ax.get_xlabel() == "M frames" and ax.xaxis.get_offset_text().get_text() == ""
    plt.close(fig)
