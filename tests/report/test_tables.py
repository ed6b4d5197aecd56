"""Paper-side-by-side tables on a FIXTURE of fake finished runs (a results CSV written in tmp_path: these numbers
are made up for the test, never results)."""

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from emml.profiles import profile_seeds
from emml.registry import load_table
from emml.report.tables import CI_SEED, MISSING, N_RESAMPLES, mean_ci, report_table

PROFILE = "quick"  # three seeds


def fake_results(table: str, root, drop: tuple[str, ...] = (), value=None) -> pd.DataFrame:
    """FIXTURE: one made-up row per declared run, as the trainer's record_result would write it."""
    rows = []
    for i, spec in enumerate(load_table(table).runs(profile_seeds(PROFILE))):
        cfg = spec.to_config(PROFILE)
        name = cfg.run_name()
        if name in drop:
            continue
        row = {
            "run_name": name,
            "table": table,
            "model": spec.model,
            "difficulty": spec.difficulty,
            "aux": spec.aux,
            "seed": spec.seed,
            "profile": PROFILE,
            "frames": cfg.frames,
            "git_sha": "fixture",
            "run_id": f"id{i}",
            "eval_episodes": 100,
            "tasks": cfg.env.tasks,
            "shaping": cfg.env.shaping,
        }
        for m in ("sgn_train", "sgn_test", "eqa_train", "eqa_test"):
            if cfg.env.tasks in ("both", m[:3]):
                row[m] = value(spec) if value else 0.1 * (spec.seed + 1)
        rows.append(row)
    df = pd.DataFrame(rows)
    path = root / table / f"{PROFILE}.csv"
    path.parent.mkdir(parents=True)
    df.to_csv(path, index=False)
    return df


def test_mean_ci_matches_scipy_on_a_known_case():
    mean, lo, hi = mean_ci([0.2, 0.4, 0.6])
    assert mean == pytest.approx(0.4)
    assert lo <= 0.4 <= hi
    ref = stats.bootstrap(
        (np.array([0.2, 0.4, 0.6]),),
        np.mean,
        method="percentile",
        n_resamples=N_RESAMPLES,
        rng=np.random.default_rng(CI_SEED),
    ).confidence_interval
    assert (lo, hi) == pytest.approx((ref.low, ref.high))


def test_mean_ci_single_seed_and_constant_values():
    assert mean_ci([0.3]) == (0.3, None, None)
    assert mean_ci([0.2, 0.2, 0.2]) == pytest.approx((0.2, 0.2, 0.2))


def test_every_cell_filled(tmp_path):
    fake_results("table2", tmp_path / "results")
    rep = report_table("table2", PROFILE, results_root=tmp_path / "results", out=tmp_path / "reports")
    assert len(rep["cells"]) == 56
    assert all(c["n"] == 3 and c["paper"] is not None for c in rep["cells"])
    cell = rep["cells"][0]  # Text only, Easy, No Aux, SGN: seeds 0.1 / 0.2 / 0.3
    assert (cell["row"], cell["difficulty"], cell["aux"], cell["metric"]) == ("Text only", "easy", False, "sgn_test")
    assert cell["mean"] == pytest.approx(0.2) and cell["lo"] <= 0.2 <= cell["hi"]
    md = (tmp_path / "reports" / "table2-quick.md").read_text()
    assert MISSING + r" \|" not in md
    assert "0.20 [" in md and r"\| 0.86" in md  # ours [CI] | paper (escaped for GFM)
    assert "differs from the paper's protocol" in md and "1,500,000–5,000,000 frames" in md
    tex = (tmp_path / "reports" / "table2-quick.tex").read_text()
    assert r"\multicolumn" in tex and "Easy" in tex and r"$\mid$ 0.96" in tex


def test_a_missing_run_is_shown_missing_not_zero(tmp_path):
    gone = "dual_attention-easy-aux-s0-quick", "dual_attention-easy-aux-s1-quick", "dual_attention-easy-aux-s2-quick"
    fake_results("table3", tmp_path / "results", drop=(*gone, "da_no_sa-easy-noaux-s2-quick"))
    rep = report_table("table3", PROFILE, results_root=tmp_path / "results", out=tmp_path / "reports")
    cells = {(c["row"], c["aux"], c["metric"]): c for c in rep["cells"]}
    multi = cells[("DA Multi-Task", True, "sgn_test")]
    assert multi["n"] == 0 and multi["mean"] is None
    assert cells[("w/o SA", False, "sgn_test")]["n"] == 2
    single = cells[("DA Single-Task", False, "eqa_test")]  # from the EQA-only runs
    assert single["n"] == 3 and single["expected"] == 3
    md = (tmp_path / "reports" / "table3-quick.md").read_text()
    line = next(x for x in md.splitlines() if x.startswith("| DA Multi-Task"))
    assert line.count(f"{MISSING} \\| 0.96") == 1 and "0.00" not in line
    assert "(n=2/3)" in md
    assert "Setting: Easy" in md  # one difficulty: moved to the caption


def test_single_seed_says_no_ci(tmp_path, monkeypatch):
    fake_results("table3", tmp_path / "results")
    monkeypatch.setattr("emml.profiles.profile_seeds", lambda profile: [0])
    rep = report_table("table3", PROFILE, results_root=tmp_path / "results", out=tmp_path / "reports")
    assert all(c["n"] == 1 and c["lo"] is None for c in rep["cells"])
    assert "n=1 seed per cell, no CI" in rep["caption"]


def test_no_results_at_all(tmp_path):
    rep = report_table("table2", "smoke", results_root=tmp_path / "none", out=tmp_path / "reports")
    assert all(c["n"] == 0 for c in rep["cells"]) and "no finished runs yet" in rep["caption"]


def test_placeholder_shows_the_papers_numbers(tmp_path, placeholder_table):
    rep = report_table(placeholder_table, PROFILE, results_root=tmp_path, out=tmp_path / "reports")
    assert len(rep["cells"]) == 28 and "PLACEHOLDER" in rep["caption"]
    md = (tmp_path / "reports" / f"{placeholder_table}-quick.md").read_text()
    assert f"{MISSING} \\| 0.47" in md
    tex = tmp_path / "reports" / "table4-quick.tex"
    report_table("table4", PROFILE, results_root=tmp_path, out=tmp_path / "reports")
    assert r"\textless{}known\_color\textgreater{}" in tex.read_text()
