"""A table's training curves from MLflow histories, on a FIXTURE: made-up runs logged to a private MLflow store and
a results CSV in tmp_path pointing at them (never results)."""

import pandas as pd
import pytest

from emml.report.curves import _mean_band, plot_table
from emml.runs.tracking import Tracker


def test_mean_band_averages_seeds_on_a_common_grid():
    import numpy as np

    x = np.array([0.0, 10.0, 20.0])
    grid, mean, band = _mean_band([(x, np.array([0.0, 0.2, 0.4])), (x, np.array([0.0, 0.4, 0.8]))])
    assert grid[0] == 0 and grid[-1] == 20
    assert abs(mean[-1] - 0.6) < 1e-9
    assert np.all(band[0] <= mean + 1e-12) and np.all(mean <= band[1] + 1e-12)
    _, _, none = _mean_band([(x, np.array([0.0, 0.2, 0.4]))])
    assert none is None


def drawn(monkeypatch) -> list:
    """The figures plot_table saves, recorded as it saves them (the files are written all the same)."""
    import emml.report.curves as curves

    figs = []
    real = curves.save

    def save(fig, path, **kw):
        figs.append(fig)
        return real(fig, path, **kw)

    monkeypatch.setattr(curves, "save", save)
    return figs


def curve(fig, title: str, label: str) -> list[tuple[float, float]]:
    """The (M frames, value) points of the line ``label`` in the panel ``title``."""
    (ax,) = [ax for ax in fig.axes if ax.get_title() == title]
    (line,) = [line for line in ax.get_lines() if line.get_label() == label]
    return [(round(float(x), 6), round(float(y), 6)) for x, y in zip(line.get_xdata(), line.get_ydata())]


def test_plot_table_skips_runs_without_history(tracking, tmp_path, monkeypatch):
    figs = drawn(monkeypatch)
    rows = []
    for seed in (0, 1, 2):
        name = f"dual_attention-easy-noaux-warm400000-s{seed}-quick"  # DA Multi-Task No Aux (issue 48)
        tracker = Tracker()
        run_id = tracker.start("table3", name)
        for step in (1024, 2048, 3072):
            tracker.log_metrics({"eval/sgn_test": 0.1 * seed + step / 4096, "eval/eqa_test": 0.2}, step=step)
        tracker.finish()
        rows.append({"run_name": name, "run_id": run_id, "seed": seed, "frames": 3072})
    rows.append({"run_name": "da_no_sa-easy-aux-s0-quick", "run_id": "not-in-this-store", "seed": 0, "frames": 3072})
    csv = tmp_path / "results" / "table3" / "quick.csv"
    csv.parent.mkdir(parents=True)
    pd.DataFrame(rows).to_csv(csv, index=False)
    paths, notes = plot_table(  # a private run root: the checkout's runs/ may hold a run of that name
        "table3", "quick", results_root=tmp_path / "results", out=tmp_path / "reports", run_root=tracking["run_root"]
    )
    assert [p.name for p in paths] == ["table3-quick-curves.png", "table3-quick-curves.pdf"]
    assert all(p.is_file() for p in paths)
    assert any("da_no_sa-easy-aux-s0-quick" in n and "no curve (MLflow run" in n for n in notes)
    (fig,) = set(figs)  # its PNG and PDF
    line = curve(fig, "SGN test: Easy, No Aux", "DA Multi-Task")  # the mean of seeds 0-2: 0.1 · seed + step / 4096
    assert (line[0], line[-1]) == ((1024.0, 0.35), (3072.0, 0.85))
    assert not [ln for ax in fig.axes for ln in ax.get_lines() if ln.get_label() == "w/o SA"]  # no history: no line


def test_plot_table_placeholder(tracking, tmp_path, placeholder_table):
    paths, notes = plot_table(placeholder_table, "quick", results_root=tmp_path, out=tmp_path)
    assert paths == [] and "placeholder" in notes[0]


def test_curves_come_from_the_run_dir_when_mlflow_lacks_the_run_and_are_never_blanked(tracking, tmp_path, monkeypatch):
    figs = drawn(monkeypatch)
    csv = tmp_path / "results" / "table3" / "quick.csv"
    csv.parent.mkdir(parents=True)
    name = "da_no_sa-easy-aux-s0-quick"  # a run table3 trains itself: its run dir is under runs/table3
    pd.DataFrame([{"run_name": name, "run_id": "from-another-machine", "seed": 0, "frames": 2048}]).to_csv(csv)
    out = tmp_path / "reports"
    kw = dict(results_root=tmp_path / "results", out=out, run_root=tmp_path / "runs")
    out.mkdir()
    (out / "table3-quick-curves.png").write_bytes(b"the committed figure")
    paths, notes = plot_table("table3", "quick", **kw)  # no history anywhere: the committed figure stays
    assert (out / "table3-quick-curves.png").read_bytes() == b"the committed figure"
    assert any("kept the existing figures" in n for n in notes)
    run = tmp_path / "runs" / "table3" / name
    run.mkdir(parents=True)
    (run / "metrics.csv").write_text("step,key,value\n1024,eval/sgn_test,0.25\n2048,eval/sgn_test,0.5\n")
    paths, notes = plot_table("table3", "quick", **kw)  # the run dir's mirror gives the curve
    assert not any(name in n for n in notes)
    line = curve(figs[-1], "SGN test: Easy, Aux", "w/o SA")
    assert (line[0], line[-1]) == ((1024.0, 0.25), (2048.0, 0.5))  # the mirror's points, on the curves' grid


def test_no_curve_and_no_earlier_figure_writes_no_empty_figure(tracking, tmp_path):
    csv = tmp_path / "results" / "table3" / "quick.csv"
    csv.parent.mkdir(parents=True)
    pd.DataFrame(
        [{"run_name": "dual_attention-easy-aux-s0-quick", "run_id": "elsewhere", "seed": 0, "frames": 64}]
    ).to_csv(csv)
    out = tmp_path / "reports"
    paths, notes = plot_table("table3", "quick", results_root=tmp_path / "results", out=out, run_root=tmp_path / "runs")
    assert paths == [] and not list(out.glob("*curves*"))  # an empty figure would read as "nothing learned"
    assert any("no figure written" in n for n in notes)


def test_the_caption_states_its_runs_deviations_and_is_the_same_bytes_twice(tracking, tmp_path, monkeypatch):
    """The caption beside the figure (not in it) is read from the drawn run's saved config: change a field there and
    it changes."""
    import json

    import emml.report.curves as curves
    from emml.config.profiles import profile_config
    from emml.experiments.tables import load_table
    from emml.report.savefig import caption_path

    texts = []
    real = curves.save
    monkeypatch.setattr(curves, "save", lambda fig, path, **kw: (texts.append(_texts(fig)), real(fig, path, **kw))[1])
    name = "dual_attention-easy-aux-s0-quick"
    csv = tmp_path / "results" / "table3" / "quick.csv"
    csv.parent.mkdir(parents=True)
    pd.DataFrame([{"run_name": name, "run_id": "elsewhere", "seed": 0, "frames": 2048, "eval_episodes": 100}]).to_csv(
        csv, index=False
    )
    spec = next(s for s in load_table("table3").runs([0]) if s.run_name("quick") == name)
    run = tmp_path / "runs" / spec.table / name  # the folder of the table that trains it
    run.mkdir(parents=True)
    (run / "metrics.csv").write_text("step,key,value\n1024,eval/sgn_test,0.25\n2048,eval/sgn_test,0.5\n")
    config = profile_config("quick", "easy", model="dual_attention", aux=True).to_dict()
    (run / "results.json").write_text(json.dumps({"config": config}))
    kw = dict(results_root=tmp_path / "results", out=tmp_path / "reports", run_root=tmp_path / "runs")
    paths, _ = plot_table("table3", "quick", **kw)
    note = caption_path(paths[0])
    first = [p.read_bytes() for p in (*paths, note)]
    assert "input 84×150 (paper 168×300, App. A) [the run]" in note.read_text()
    assert "x_S = h·w·vec(x_spat) (paper vec(x_spat), text after Eq. 5) [the run]" in note.read_text()
    assert "input 84×150" not in texts[-1] and "Deviations" not in texts[-1]  # the figure carries no notes
    plot_table("table3", "quick", **kw)
    assert [p.read_bytes() for p in (*paths, note)] == first  # no date, no version: make reports changes no byte
    config["env"].update(height=168, width=300)
    (run / "results.json").write_text(json.dumps({"config": config}))
    plot_table("table3", "quick", **kw)
    assert "input" not in note.read_text() and "x_S = h·w·vec(x_spat)" in note.read_text()


def test_many_rows_of_panels_are_lowered_to_fit_a_page():
    from emml.report.curves import CHROME_INCHES, PANEL_INCHES, figure_height
    from emml.report.savefig import PAGE_HEIGHT_INCHES

    assert figure_height(2) == pytest.approx(CHROME_INCHES + 2 * PANEL_INCHES)  # room: the panels' own height
    for rows in (4, 5, 8):
        assert figure_height(rows) <= PAGE_HEIGHT_INCHES + 1e-9
    assert figure_height(8) == pytest.approx(PAGE_HEIGHT_INCHES)  # lowered to the page, not below it


def _texts(fig) -> str:
    """Every text of the figure, its wrapped lines joined again."""
    from matplotlib.text import Text

    return " ".join(t.get_text().replace("\n", " ") for t in fig.findobj(Text))


def test_the_figure_is_a_page_wide_nothing_cut_x_in_m_frames_dual_attention_over_the_rest(
    tracking, tmp_path, monkeypatch
):
    import emml.report.curves as curves
    from emml.report.savefig import PAGE_INCHES, outside
    from tests.report.test_efficiency import write_curves
    from tests.report.test_tables import fake_results, fake_run_dirs

    fake_results("table2", tmp_path / "results")
    fake_run_dirs("table2", tmp_path / "runs")
    write_curves(tmp_path / "runs", "table2", lambda s: 0.5)
    figs = []
    monkeypatch.setattr(curves, "save", lambda fig, path, **kw: (figs.append(fig), path)[1])
    kw = dict(results_root=tmp_path / "results", out=tmp_path / "reports", run_root=tmp_path / "runs")
    plot_table("table2", "quick", **kw)
    fig = figs[0]
    assert fig.get_size_inches()[0] == PAGE_INCHES
    assert outside(fig) == []  # every title, label, tick label and legend entry inside the canvas
    panels = [ax for ax in fig.axes if ax.get_title()]
    assert {ax.get_title() for ax in panels} == {
        f"{m} test: {d}, {a}" for m in ("SGN", "EQA") for d in ("Easy", "Hard") for a in ("No Aux", "Aux")
    }
    for ax in panels:
        assert ax.get_xlabel() == "M frames" and ax.xaxis.get_offset_text().get_text() == ""  # no '1e6'
        assert ax.xaxis.get_major_formatter()(1.5e6, 0) == "1.5"  # 1.5M frames reads 1.5
        ticks = [float(t.get_text()) for t in ax.get_xticklabels() if t.get_text()]
        assert ticks and max(ticks) <= 6, ticks  # millions: at most 5M frames here
        width = {line.get_label(): line.get_linewidth() for line in ax.get_lines()}
        assert width["Dual-Attention"] > max(w for k, w in width.items() if k in ("GA", "FiLM", "Concat"))


def test_the_dotted_chance_line_is_the_tasks_blind_ceiling_not_the_text_only_runs(tracking, tmp_path, monkeypatch):
    """The Text only runs score 0.9 here; the chance line of each panel stays the task's ceiling enumerated from the
    episode generator: SGN test 0.2 (the goal's slot, one of five), EQA test 0.5625 (the best fixed answer per
    question; tests/envs/test_ceiling.py) in Easy and Hard alike (one generator)."""
    from matplotlib.text import Text

    import emml.report.curves as curves
    from tests.report.test_efficiency import write_curves
    from tests.report.test_tables import fake_results, fake_run_dirs

    fake_results("table2", tmp_path / "results", value=lambda spec: 0.9 if spec.model == "text_only" else 0.5)
    fake_run_dirs("table2", tmp_path / "runs")
    write_curves(tmp_path / "runs", "table2", lambda s: 0.5)
    figs = []
    monkeypatch.setattr(curves, "save", lambda fig, path, **kw: (figs.append(fig), path)[1])
    kw = dict(results_root=tmp_path / "results", out=tmp_path / "reports", run_root=tmp_path / "runs")
    plot_table("table2", "quick", **kw)
    fig = figs[0]
    lines = {}
    for ax in fig.axes:
        dotted = [line for line in ax.get_lines() if line.get_linestyle() == ":"]
        if ax.get_title():
            (line,) = dotted
            lines[ax.get_title()] = round(float(line.get_ydata()[0]), 6)
    assert lines == {
        f"{m} test: {d}, {a}": (0.2 if m == "SGN" else 0.5625)
        for m in ("SGN", "EQA")
        for d in ("Easy", "Hard")
        for a in ("No Aux", "Aux")
    }
    texts = {t.get_text() for t in fig.findobj(Text)}
    assert {"blind ceiling 0.20", "blind ceiling 0.56"} <= texts
