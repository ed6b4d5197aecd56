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


def claims_like(label: int = 40):
    """A figure drawn as the claims figure is: long tick labels beside a narrow axes, and a legend of six entries
    anchored above the axes' middle, wider than the axes. Laid out once from its first positions at 120 dpi, its
    last entry leaves the canvas."""
    from matplotlib.lines import Line2D

    n = 22
    fig, ax = plt.subplots(figsize=(7, 0.8 + 0.22 * n), layout="constrained")
    ax.plot([0, 1], [0, n])
    ax.set_yticks(range(n), [f"{'x' * (label - 12)}-claim-{i}: not supported (1)" for i in range(n)])
    names = ("paper", "ours (mean)", "ours (a seed)", "SGN", "EQA", "diag/*")
    handles = [Line2D([], [], ls="none", marker="o", label=t) for t in names]
    ax.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=6, fontsize=6)
    ax.set_title("Ours against the paper per claim (label: status, seeds)", pad=14)
    return fig


def test_a_figure_is_settled_at_its_files_dpi_before_it_is_written(tmp_path):
    """The PNG written first is drawn from a layout that holds: every text inside its canvas, as in the PDF."""
    from emml.report.savefig import cut, save

    assert outside(claims_like(), 120) == ["diag/*"]  # one layout from the first positions: the entry is cut
    for suffix in (".png", ".pdf"):
        fig, drawn = claims_like(), []
        fig.canvas.mpl_connect("draw_event", lambda e, fig=fig, drawn=drawn: drawn.append(cut(fig, e.renderer)))
        save(fig, tmp_path / f"claims{suffix}")
        assert drawn and drawn[-1] == [], suffix  # the file's own draw (the last): nothing cut
        plt.close(fig)


def test_each_format_is_settled_at_the_dpi_it_is_drawn_at(tmp_path, monkeypatch):
    import emml.report.savefig as savefig

    dpis = []
    monkeypatch.setattr(savefig, "settle", lambda fig, dpi: dpis.append(dpi))
    fig, _ = plt.subplots(layout="constrained")
    for name, kw in (("a.png", {}), ("b.png", {"dpi": 150}), ("c.pdf", {"dpi": 150}), ("d.svg", {})):
        savefig.save(fig, tmp_path / name, **kw)
    assert dpis == [120, 150, 72, 72]  # savefig.dpi, the dpi asked, points for vector formats whatever asked
    plt.close(fig)


def test_a_figures_caption_is_beside_it():
    from emml.report.savefig import caption_path

    assert caption_path("reports/table2-quick-curves.png").as_posix() == "reports/table2-quick-curves.txt"
    assert caption_path("reports/table2-quick-curves.pdf") == caption_path("reports/table2-quick-curves.png")
