"""Every figure the reports write, checked as it is written: on a FIXTURE (made-up results, run dirs and curves in
tmp_path; never results/, runs/ or reports/), `emml.report.savefig.save` is wrapped so that each file saved, PNG and
PDF, is checked on the draw that writes it: no text leaves its canvas (`emml.report.savefig.cut`, at the file's own
dpi and layout), and the figure fits a page (at most `PAGE_INCHES` × `PAGE_HEIGHT_INCHES`)."""

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import emml.report.savefig as savefig
from emml.report.savefig import PAGE_HEIGHT_INCHES, PAGE_INCHES, caption_path
from tests.report.test_efficiency import write_curves
from tests.report.test_tables import PROFILE, fake_results, fake_run_dirs


@dataclass
class Saved:
    """One file a figure was written to: its name, size (in) and the texts its own draw put outside the canvas."""

    name: str
    width: float
    height: float
    cut: list


def watch(monkeypatch) -> list[Saved]:
    """Wrap `savefig.save`, and every module's name for it, so each file saved is recorded as a `Saved`."""
    real, seen = savefig.save, []

    def save(fig, path, **kw):
        drawn = []
        cid = fig.canvas.mpl_connect("draw_event", lambda e: drawn.append(savefig.cut(fig, e.renderer)))
        try:
            out = real(fig, path, **kw)
        finally:
            fig.canvas.mpl_disconnect(cid)
        width, height = fig.get_size_inches()
        seen.append(Saved(Path(path).name, float(width), float(height), drawn[-1]))  # the file's own draw: last
        return out

    for module in [m for n, m in sys.modules.items() if n.startswith("emml.") and m is not None]:
        if getattr(module, "save", None) is real:
            monkeypatch.setattr(module, "save", save)
    monkeypatch.setattr(savefig, "save", save)  # modules imported later, or importing it in a function, take this
    return seen


def fits(saved: Saved) -> list[str]:
    """What is wrong with one file: texts cut, wider or taller than a page (empty: nothing)."""
    wrong = [f"{saved.name}: cut {saved.cut}"] if saved.cut else []
    if saved.width > PAGE_INCHES + 1e-9:
        wrong.append(f"{saved.name}: {saved.width:.2f} in wide > {PAGE_INCHES}")
    if saved.height > PAGE_HEIGHT_INCHES + 1e-9:
        wrong.append(f"{saved.name}: {saved.height:.2f} in tall > {PAGE_HEIGHT_INCHES}")
    return wrong


def test_every_figure_the_reports_write_is_inside_its_canvas_png_and_pdf_and_fits_a_page(tmp_path, monkeypatch):
    """`emml reports` (write_reports) on the fixture's Tables 2, 3 and 4, and an experiment's curves and page (the
    index lists no experiment); the curves' notes are their caption on the page, under the figure."""
    from emml.report.curves import plot_table
    from emml.report.index import write_reports
    from emml.report.tables import report_table

    results, runs, out = tmp_path / "results", tmp_path / "runs", tmp_path / "reports"
    tables = ("table2", "table3", "table4", "experiments/noaux_schedule")
    for table in tables:
        fake_results(table, results)
        fake_run_dirs(table, runs)
        write_curves(runs, table, lambda spec: 0.5)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path}/mlflow.db")
    seen = watch(monkeypatch)
    write_reports(out, results, runs, log=lambda m: None)
    plot_table(tables[-1], PROFILE, results, out, runs)  # the curves first: the page embeds them
    report_table(tables[-1], PROFILE, results, out, runs)

    names = {s.name for s in seen}
    for stem in ("claims-quick", "table2-quick-curves", "table4-quick-curves", "noaux_schedule-quick-curves"):
        assert {f"{stem}.png", f"{stem}.pdf"} <= names, stem  # each figure's two files, both checked
    # the field figure: 18.6 and 15.6 in tall on one page here before it was cut into pages (emml/report/field.py)
    assert {"table2-quick-rliable.pdf", "table2-quick-rliable-2.pdf", "table3-quick-rliable.pdf"} <= names
    assert [s.name for s in seen if s.cut] == []
    assert [w for s in seen for w in fits(s)] == []

    note = caption_path(out / "table3-quick-curves.png").read_text().strip()
    assert note.startswith("*Figure: table3 [quick], greedy accuracy") and "Deviations from the paper:" in note
    page = (out / "table3-quick.md").read_text()
    image = page.index("![table3-quick-curves](table3-quick-curves.png)")
    assert image < page.index(note) < page.index("![table3-quick-rliable]")  # under the figure it describes
    pages = sorted(n for n in names if n.startswith("table2-quick-rliable") and n.endswith(".png"))
    text = (out / "table2-quick.md").read_text()
    assert pages and all(f"]({n})" in text for n in pages)  # the table's page shows every page of it


def test_the_channels_and_attention_figures_fit_a_page(tmp_path, monkeypatch):
    """The best run's figures (emml/report/visualize.py) on a made-up episode (no engine, no model): seven words,
    six steps, square frames (taller than any profile's: the most a row of panels asks)."""
    import emml.report.visualize as visualize

    seen = watch(monkeypatch)
    words = ("red", "green", "torch", "pillar", "smallest", "tall", "armor", "blue", "go", "to", "the")
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 255, (84, 84, 3), dtype=np.uint8) for _ in range(12)]
    maps = [rng.random((len(words), 5, 9)) for _ in frames]
    ep = visualize.Episode(
        "go to the red torch", "sgn", words, rng.random(len(words)), frames=frames,
        attention=[m[0] for m in maps], answers=[rng.random(len(words)) for _ in frames], channels=maps,
        labels=maps, moves=[0] * len(frames),
    )  # fmt: skip
    visualize.attention_figure(ep, tmp_path / "attention.png")
    monkeypatch.setattr(visualize, "record_episode", lambda *a, **k: ep)
    visualize.channels_figure([("aux", None), ("no aux", None)], None, tmp_path / "channels.png")
    assert [s.name for s in seen] == ["attention.png", "channels.png"]
    assert [w for s in seen for w in fits(s)] == []
