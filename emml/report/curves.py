"""Training curves from MLflow metric histories: training success per task vs frames (like the paper's Figures
7 and 8), with the greedy evaluation points."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from emml.report.savefig import save  # noqa: E402
from emml.runs.tracking import metric_history  # noqa: E402

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
    save(fig, path, dpi=120)
    plt.close(fig)
    return path


# --- a table's training curves (the paper's Figures 7, 8: Table 2; Figure 9: Table 3) ----------------------------

TRAIN_KEYS = (("train/success_sgn", "SGN"), ("train/success_eqa", "EQA"))
GRID_POINTS = 300
"""Curves are resampled on at most this many frame values before averaging seeds (keeps the bootstrap cheap)."""


def _mean_band(curves: list[tuple[np.ndarray, np.ndarray]]):
    """Common frame grid (up to the shortest seed's end), the seed mean and a 95% percentile-bootstrap band
    (scipy.stats.bootstrap over seeds, per grid point; None with one seed)."""
    from scipy import stats

    end = min(x[-1] for x, _ in curves)
    start = max(x[0] for x, _ in curves)
    grid = np.linspace(start, end, GRID_POINTS) if end > start else np.array([end])
    ys = np.stack([np.interp(grid, x, y) for x, y in curves])
    mean = ys.mean(axis=0)
    if len(curves) < 2:
        return grid, mean, None
    res = stats.bootstrap(
        (ys,), np.mean, axis=0, method="percentile", n_resamples=2000, rng=np.random.default_rng(0), vectorized=True
    )
    low, high = res.confidence_interval
    flat = np.all(ys == ys[0], axis=0)  # identical seeds: a degenerate bootstrap; the band is the mean
    return grid, mean, (np.where(flat, mean, low), np.where(flat, mean, high))


def plot_table(
    name: str,
    profile: str,
    results_root: str | Path | None = None,
    out: str | Path | None = None,
    run_root: str | Path | None = None,
) -> tuple[list[Path], list[str]]:
    """Training accuracy vs frames for every row of table `name` under `profile`: a panel per (task, difficulty,
    aux), one line per row (mean over seeds, CI band), and under the panels the deviations from the paper of the
    runs drawn, read from their configs (emml/report/deviations.py). Runs come from results/<name>/<profile>.csv
    (their run_id), curves from MLflow, else from the run dir's metrics.csv (under ``run_root``, default: the
    profile's); a run with neither is skipped with a note. When no run has a curve here, existing figures are kept
    rather than replaced by empty ones. Returns (paths, notes)."""
    from emml.config.profiles import profile_config, profile_seeds
    from emml.experiments.tables import load_table
    from emml.report import deviations
    from emml.report.tables import AUX_LABELS, DIFFICULTY_LABELS, reports_dir, table_results
    from emml.runs.rundir import METRICS, path_of
    from emml.runs.tracking import read_mirror

    table = load_table(name)
    run_root = run_root if run_root is not None else profile_config(profile).run_root
    out = reports_dir(profile, out)
    notes: list[str] = []
    if table.placeholder:
        return [], [f"{name} is a placeholder: no runs, no curves"]
    results = table_results(table, profile, results_root)  # its own rows, and those it borrows (Table 3's DA)
    run_ids = dict(zip(results["run_name"], results["run_id"]))
    panels = [(d, a) for d in table.difficulties for a in table.aux]
    fig, axes = plt.subplots(
        len(TRAIN_KEYS), len(panels), figsize=(3.6 * len(panels), 3.0 * len(TRAIN_KEYS)), squeeze=False, sharey=True
    )
    specs = table.runs(profile_seeds(profile))
    cache: dict[str, dict] = {}
    drawn: dict = {}  # run name → RunSpec of every run with a curve in the figure
    plotted = False
    for j, (difficulty, aux) in enumerate(panels):
        for i, (key, task) in enumerate(TRAIN_KEYS):
            ax = axes[i][j]
            for k, row in enumerate(table.curve_rows()):
                curves = []
                for spec in specs:
                    if spec.row != row or spec.difficulty != difficulty or spec.aux != aux:
                        continue
                    rname = spec.run_name(profile)
                    if rname not in run_ids:
                        continue
                    if rname not in cache:
                        cache[rname] = {k: _history(run_ids[rname], k) for k, _ in TRAIN_KEYS}
                        if not any(cache[rname].values()):  # another store's run: its run dir may be here
                            mirror = read_mirror(path_of(run_root, spec.table, rname) / METRICS)
                            cache[rname] = {k: [(st, v) for st, kk, v in mirror if kk == k] for k, _ in TRAIN_KEYS}
                        if not any(cache[rname].values()):
                            notes.append(
                                f"{rname}: no curve (MLflow run {run_ids[rname]} not here, no run dir); skipped"
                            )
                    hist = cache[rname][key]
                    if hist:
                        steps, values = zip(*hist)
                        curves.append((np.asarray(steps, float), np.asarray(values, float)))
                        drawn.setdefault(rname, spec)
                if not curves:
                    continue
                plotted = True
                grid, mean, band = _mean_band(curves)
                color = f"C{k % 10}"
                ax.plot(
                    grid,
                    mean,
                    color=color,
                    lw=1.2,
                    marker="o" if len(grid) == 1 else None,
                    label=f"{row} (n={len(curves)})",
                )
                if band is not None:
                    ax.fill_between(grid, band[0], band[1], color=color, alpha=0.2, lw=0)
            title = f"{task} — {DIFFICULTY_LABELS.get(difficulty, difficulty)}, {AUX_LABELS[aux]}"
            ax.set_title(title, fontsize=9)
            ax.set_ylim(-0.02, 1.02)
            ax.grid(alpha=0.3)
            if i == len(TRAIN_KEYS) - 1:
                ax.set_xlabel("frames (agent steps)")
            if j == 0:
                ax.set_ylabel("training accuracy")
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=6, loc="upper left")
    note = "" if profile == "paper" else f"\nprofile '{profile}' is not the paper's protocol: its deviations below"
    fig.suptitle(
        f"{name} [{profile}]: training accuracy (100-episode success), seed mean, 95% bootstrap band{note}", fontsize=9
    )
    rows = {r["run_name"]: r for r in results.to_dict("records")} if not results.empty else {}
    shown = [deviations.shown_run(spec, profile, run_root, rows.get(r)) for r, spec in drawn.items()]
    footer = deviations.sentence(deviations.summarise(shown)) if shown else ""
    _footer(fig, footer)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{name}-{profile}-curves.png", out / f"{name}-{profile}-curves.pdf"]
    if not plotted:  # never an empty figure: keep what an earlier machine drew, or draw nothing
        plt.close(fig)
        kept = [p for p in paths if p.exists()]
        what = "kept the existing figures" if kept else "no figure written"
        return kept, notes + [f"no run of {name} [{profile}] has a curve here: {what}"]
    for p in paths:
        save(fig, p, dpi=120)
    plt.close(fig)
    return paths, notes


FOOTER_CHARS_PER_INCH = 21
"""Characters of the 6-point footer per inch of figure width (wrapping)."""
FOOTER_LINE_INCHES = 0.11


def _footer(fig, text: str) -> None:
    """``text`` wrapped under the panels, the figure grown to hold it."""
    import textwrap

    w, h = fig.get_size_inches()
    lines = textwrap.wrap(text, int(w * FOOTER_CHARS_PER_INCH)) if text else []
    extra = FOOTER_LINE_INCHES * len(lines) + (0.1 if lines else 0)
    fig.set_size_inches(w, h + extra)
    fig.tight_layout(rect=(0, extra / (h + extra), 1, 1))
    if lines:
        fig.text(0.01, 0.005, "\n".join(lines), fontsize=6, ha="left", va="bottom")


def _history(run_id: str, key: str) -> list[tuple[int, float]] | None:
    """The metric's history; [] when the run never logged it (a single-task run) or MLflow lacks the run, None when
    the store cannot be read for it."""
    try:
        return metric_history(str(run_id), key)
    except Exception:  # the run is not in this MLflow store (another machine's database, a fresh checkout)
        return None
