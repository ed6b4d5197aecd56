"""Paper-side-by-side tables on a FIXTURE of fake finished runs (a results CSV, and run dirs with the results.json of
each run, written in tmp_path: these numbers are made up for the test, never results)."""

import json
import re

import pandas as pd
import pytest

from emml.config.profiles import profile_seeds, resolve_profile
from emml.experiments.tables import load_table
from emml.report.cells import MISSING
from emml.report.tables import report_table, reports_dir
from emml.runs.naming import run_name

PROFILE = "quick"  # three seeds


def fake_results(table: str, root, drop: tuple[str, ...] = (), value=None) -> pd.DataFrame:
    """FIXTURE: one made-up row per declared run, as the trainer's record_result would write it."""
    rows = []
    for i, spec in enumerate(load_table(table).runs(profile_seeds(PROFILE), PROFILE)):
        cfg = spec.to_config(PROFILE)
        name = run_name(cfg)
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


def fake_run_dirs(table: str, run_root, change=None) -> None:
    """FIXTURE: each declared run's dir with a results.json holding its config, as the trainer writes it;
    ``change(spec, config_dict)`` edits a run's saved config first."""
    for spec in load_table(table).runs(profile_seeds(PROFILE), PROFILE):
        config = spec.to_config(PROFILE).to_dict()
        if change is not None:
            change(spec, config)
        folder = run_root / spec.table / spec.run_name(PROFILE)  # a borrowed row's runs are in their table's folder
        folder.mkdir(parents=True, exist_ok=True)  # Table 3 borrows Table 2's DA runs
        (folder / "results.json").write_text(json.dumps({"run_name": folder.name, "config": config}))


def report(table: str, tmp_path, **kw) -> dict:
    """report_table on the fixture's roots in tmp_path (never the checkout's runs/, results/, reports/)."""
    roots = dict(results_root=tmp_path / "results", out=tmp_path / "reports", run_root=tmp_path / "runs")
    return report_table(table, kw.pop("profile", PROFILE), **{**roots, **kw})


def test_every_cell_filled_with_each_seeds_value(tmp_path):
    fake_results("table2", tmp_path / "results")
    rep = report("table2", tmp_path)
    assert len(rep["cells"]) == 56
    five = ("Dual-Attention", "easy", True)  # table2.toml's more_seeds: the stated model's Easy · Aux on seeds 0-4
    assert all(c["n"] == (5 if (c["row"], c["difficulty"], c["aux"]) == five else 3) for c in rep["cells"])
    assert all(c["paper"] is not None for c in rep["cells"])
    cell = rep["cells"][0]  # Text only, Easy, No Aux, SGN: seeds 0.1 / 0.2 / 0.3
    assert (cell["row"], cell["difficulty"], cell["aux"], cell["metric"]) == ("Text only", "easy", False, "sgn_test")
    assert cell["mean"] == pytest.approx(0.2) and cell["values"] == pytest.approx([0.1, 0.2, 0.3])
    md = (tmp_path / "reports" / "table2-quick.md").read_text()
    assert MISSING + r" \|" not in md
    assert r"0.20 (0.10 · 0.20 · 0.30) \| 0.86" in md  # mean (each seed) | paper (escaped for GFM)
    assert "[" not in md.split("| Model")[1].split("\n\n")[0]  # no bootstrap CI over three values in the cells
    assert "not the paper's protocol" in md and "1,500,000–5,000,000 frames" in md
    tex = (tmp_path / "reports" / "table2-quick.tex").read_text()  # its layout: tests/report/test_tex.py
    assert "\\textbf{Dual-Attention} & 0.20 & 0.86 & 0.20 & 0.53 & 0.30 & 0.96 & 0.30 & 0.58 \\\\" in tex  # 5 seeds


def test_a_missing_run_is_shown_missing_not_zero(tmp_path):
    gone = tuple(f"dual_attention-easy-aux-s{s}-quick" for s in range(5))  # its five seeds (more_seeds)
    fake_results("table3", tmp_path / "results", drop=(*gone, "da_no_sa-easy-noaux-warm400000-s2-quick"))
    rep = report("table3", tmp_path)
    cells = {(c["row"], c["aux"], c["metric"]): c for c in rep["cells"]}
    multi = cells[("DA Multi-Task", True, "sgn_test")]
    assert multi["n"] == 0 and multi["mean"] is None
    assert cells[("w/o SA", False, "sgn_test")]["n"] == 2
    single = cells[("DA Single-Task", False, "eqa_test")]  # from the EQA-only runs
    assert single["n"] == 3 and single["expected"] == 3
    md = (tmp_path / "reports" / "table3-quick.md").read_text()
    line = next(x for x in md.splitlines() if x.startswith("| DA Multi-Task"))
    assert line.count(f"{MISSING} \\| 0.96") == 1 and "0.00" not in line
    assert "0.15 (0.10 · 0.20; n=2/3)" in md  # the seeds there, and how many of the declared
    assert "Setting: Easy" in md  # one difficulty: moved to the caption


def test_one_seed_of_three_says_so_and_one_of_one_shows_the_value(tmp_path, monkeypatch):
    fake_results("table3", tmp_path / "results", drop=tuple(f"da_no_sa-easy-aux-s{s}-quick" for s in (1, 2)))
    md = (report("table3", tmp_path), (tmp_path / "reports" / "table3-quick.md").read_text())[1]
    assert "0.10 (n=1/3)" in md
    import dataclasses

    import emml.report.plan as plan_module

    monkeypatch.setattr("emml.config.profiles.profile_seeds", lambda profile: [0])  # a profile of one seed
    monkeypatch.setattr(plan_module, "resolve_profile", lambda p: dataclasses.replace(resolve_profile(p), seeds=(0,)))
    rep = report("table3", tmp_path)
    assert all(c["n"] == 1 for c in rep["cells"] if (c["row"], c["aux"]) != ("DA Multi-Task", True))  # + more_seeds
    line = next(x for x in (tmp_path / "reports" / "table3-quick.md").read_text().splitlines() if "| w/o GA1" in x)
    assert "0.10 \\|" in line and "(" not in line


def test_no_results_at_all_shows_the_declared_deviations(tmp_path):
    rep = report("table2", tmp_path, profile="smoke", results_root=tmp_path / "none")
    assert all(c["n"] == 0 for c in rep["cells"]) and "no finished runs yet" in rep["caption"]
    md = (tmp_path / "reports" / "table2-smoke.md").read_text()
    assert "input 60×108 (paper 168×300, App. A): all 28 runs" in md
    assert "28 runs from the registry's config as declared (no run finished yet)" in md and rep["aggregate"] is None


def test_the_caption_lists_the_deviations_read_from_the_runs_saved_configs(tmp_path):
    """Change a field in one run's saved config and the caption changes: nothing is written by hand."""
    fake_results("table3", tmp_path / "results")
    fake_run_dirs("table3", tmp_path / "runs")
    rep = report("table3", tmp_path)
    md = (tmp_path / "reports" / "table3-quick.md").read_text()
    devs = dict(rep["deviations"]["deviations"])
    assert devs["input 84×150 (paper 168×300, App. A)"] == "all 50 runs"
    assert devs["frames 1.5M (paper 10M, §5.1)"] == "all 50 runs"
    assert "- x_S = h·w·vec(x_spat) (paper vec(x_spat), text after Eq. 5): all but the w/o SA runs (44 of 50)" in md
    assert "50 runs from their saved config" in md and "reward shaping" not in md  # the w/o RS row is the experiment
    # the No Aux warm-up (issues 48, 61): said once, with the rows it applies to (every row of Table 3)
    gated = [line for line in devs if line.startswith("answer kept off the image encoder for the first 400,000")]
    assert len(gated) == 1 and devs[gated[0]] == (
        "the No Aux runs of every row: w/o SA, w/o GA1, w/o GA2, w/o Task Indicator, w/o Reward Shaping, "
        "DA Single-Task, DA Multi-Task"
    ), devs
    choices = dict(rep["deviations"]["choices"])
    assert choices["wrong-object/answer reward 0 (paper silent: §5.1 names only +1 and -0.001 per step)"] == (
        "all 50 runs"
    )
    assert choices["score: greedy, 100 episodes per task and split (paper silent on its evaluation size)"] == (
        "all 50 runs"  # from the results rows (the evaluation the score came from), not the config
    )
    tex = (tmp_path / "reports" / "table3-quick.tex").read_text()
    assert r"input 84$\times$150 (paper 168$\times$300, App. A) [all 50 runs]" in tex  # ASCII: a bare pdflatex

    def paper_input_unscaled(spec, config):
        if spec.row == "DA Multi-Task" and spec.seed == 0:
            config["env"].update(height=168, width=300)
            config["model_options"] = {"state_scale": False}
            config["env"]["wrong_reward"] = -0.2

    (tmp_path / "runs").rename(tmp_path / "old-runs")
    fake_run_dirs("table3", tmp_path / "runs", paper_input_unscaled)
    rep = report("table3", tmp_path)
    devs, choices = dict(rep["deviations"]["deviations"]), dict(rep["deviations"]["choices"])
    assert devs["input 84×150 (paper 168×300, App. A)"].startswith("48 of 50 runs: ")
    assert devs["x_S = h·w·vec(x_spat) (paper vec(x_spat), text after Eq. 5)"].startswith("42 of 50 runs: ")
    wrong = "wrong-object/answer reward -0.2 (paper silent: §5.1 names only +1 and -0.001 per step)"
    two = "dual_attention-easy-aux-s0-quick, dual_attention-easy-noaux-warm400000-s0-quick"
    assert choices[wrong] == f"2 of 50 runs: {two}"
    assert wrong in (tmp_path / "reports" / "table3-quick.md").read_text()


def test_a_run_without_its_run_dir_falls_back_to_its_registry_config_and_says_so(tmp_path):
    fake_results("table3", tmp_path / "results")
    fake_run_dirs("table3", tmp_path / "runs")
    gone = tmp_path / "runs" / "table3" / "da_no_sa-easy-aux-s0-quick"
    (gone / "results.json").unlink()
    gone.rmdir()
    partial = tmp_path / "runs" / "table3" / "da_no_sa-easy-aux-s1-quick" / "results.json"
    partial.write_text(json.dumps({"run_name": "da_no_sa-easy-aux-s1-quick"}))  # finished before configs were saved
    rep = report("table3", tmp_path)
    sources = rep["deviations"]["sources"]
    assert "48 runs from their saved config" in sources
    assert "1 run from the registry's config (their results.json has no config yet: `emml backfill-config`)" in sources
    assert "1 run from the registry's config (no run dir here: reference rows of the results CSV)" in sources


def no_field_figure(monkeypatch) -> None:
    """The report without its rliable figure: the aggregate tests read the table under the report, and the figure
    (test_aggregate.py's business) is ~80% of a report's time, which `make mutate` paid per mutant of aggregate.py."""
    monkeypatch.setattr("emml.report.field.plot_field", lambda *a: [])


def test_the_aggregate_under_the_table(tmp_path, monkeypatch):
    """Per setting and metric: IQM per row, the mean difference to Dual-Attention and P(Dual-Attention > row), each
    with its interval when both rows have runs to resample; reproducible to the digit."""
    no_field_figure(monkeypatch)

    def value(spec):  # Dual-Attention ahead of every baseline in every cell
        return 0.5 + 0.1 * spec.seed if spec.row == "Dual-Attention" else 0.1 * (spec.seed + 1)

    fake_results("table2", tmp_path / "results", value=value)
    rep = report("table2", tmp_path)
    lines = {(r["Setting"], r["Model"]): r for r in rep["aggregate"]["rows"]}
    assert len(lines) == 4 * 7  # Easy/Hard × Aux/No Aux apart, every row in each
    da = lines[("Easy · No Aux", "Dual-Attention")]  # three seeds (Easy · Aux has five: more_seeds)
    value, lo, hi = map(
        float, re.match(r"(\S+) \[(\S+), (\S+)\] \(3 runs in 1 cell\)", da["SGN IQM [95% CI]"]).groups()
    )
    assert value == 0.60 and 0.5 <= lo < value < hi <= 0.7  # IQM (the mean) of 0.5 / 0.6 / 0.7 in one cell
    ga = lines[("Hard · No Aux", "GA")]
    assert ga["SGN IQM [95% CI]"].startswith("0.20 [")
    assert re.match(
        r"\+0\.40 \[\+0\.\d\d, \+0\.\d\d\] \(3 vs 3 runs in 1 cell\)", ga["SGN: Dual-Attention − row [95% CI]"]
    )
    assert ga["SGN: P(Dual-Attention > row)"].startswith("1.00 [")
    assert da["SGN: P(Dual-Attention > row)"] == ""
    md = (tmp_path / "reports" / "table2-quick.md").read_text()
    assert "stratified" not in md and "rliable" in md and "Aux and No Aux apart" in md
    first = md
    report("table2", tmp_path)
    assert (tmp_path / "reports" / "table2-quick.md").read_text() == first


def test_the_aggregate_compares_like_with_like_issue_49(tmp_path, monkeypatch):
    """Issue 49's Table 3: DA Multi-Task has an Aux (0.93) and a No Aux (0.19) cell on seed 0, the ablations Aux only
    (0.89-0.93). The aggregate read 'DA Multi-Task SGN IQM 0.56' beside 0.89-0.93 (both of its cells pooled) and
    P(DA > row) '1.00 [1.00, 1.00] (n=4)' from one cell; now each setting is compared apart, one run per cell has no
    interval, and the difference is shown beside P."""
    no_field_figure(monkeypatch)
    sgn = {"DA Multi-Task": 0.934, "w/o GA2": 0.91, "w/o Task Indicator": 0.93, "w/o Reward Shaping": 0.90}
    keep = {"dual_attention-easy-noaux-warm400000-s0-quick"}

    def value(spec):
        if spec.row == "DA Multi-Task" and not spec.aux:
            return 0.194
        return sgn.get(spec.row, 0.3)

    everything = fake_results("table3", tmp_path / "results", value=value)
    seed0_aux = everything[(everything["seed"] == 0) & everything["aux"]]
    drop = set(everything["run_name"]) - set(seed0_aux["run_name"]) - keep
    (tmp_path / "results" / "table3" / "quick.csv").unlink()
    (tmp_path / "results" / "table3").rmdir()
    fake_results("table3", tmp_path / "results", drop=tuple(drop), value=value)
    rep = report("table3", tmp_path)
    lines = {(r["Setting"], r["Model"]): r for r in rep["aggregate"]["rows"]}
    assert lines[("Easy · Aux", "DA Multi-Task")]["SGN IQM [95% CI]"] == "0.93 (1 run in 1 cell: no interval)"
    assert lines[("Easy · No Aux", "DA Multi-Task")]["SGN IQM [95% CI]"] == "0.19 (1 run in 1 cell: no interval)"
    assert {k for k in lines if k[0] == "Easy · No Aux"} == {("Easy · No Aux", "DA Multi-Task")}  # nothing to compare
    ga2 = lines[("Easy · Aux", "w/o GA2")]
    assert ga2["SGN: DA Multi-Task − row [95% CI]"] == "+0.02 (1 vs 1 run in 1 cell: no interval)"
    assert ga2["SGN: P(DA Multi-Task > row)"] == "1.00 (1 vs 1 run in 1 cell: no interval)"
    page = (tmp_path / "reports" / "table3-quick.md").read_text()
    aggregate = page.split("| Setting")[1].split("### Sample efficiency")[0]  # not the chance line's EQA test 0.56
    assert "0.56" not in aggregate and "[1.00, 1.00]" not in aggregate and "n=4" not in aggregate


def test_a_report_written_twice_is_the_same_bytes(tmp_path):
    fake_results("table2", tmp_path / "results")
    fake_run_dirs("table2", tmp_path / "runs")
    report("table2", tmp_path)
    first = {p.name: p.read_bytes() for p in (tmp_path / "reports").iterdir()}
    report("table2", tmp_path)
    assert {p.name: p.read_bytes() for p in (tmp_path / "reports").iterdir()} == first


def test_smoke_reports_are_not_written_under_the_committed_reports(tmp_path):
    from emml.config.paths import project_root

    assert reports_dir(resolve_profile("smoke")) == project_root() / "scratch" / "reports"
    assert reports_dir(resolve_profile("quick")) == project_root() / "reports"
    committed = project_root() / "reports" / "table2-smoke.md"
    before = committed.read_bytes() if committed.exists() else None
    with pytest.raises(ValueError, match="the 'smoke' profile's numbers are not results"):
        report("table2", tmp_path, profile="smoke", out=project_root() / "reports")
    assert (committed.read_bytes() if committed.exists() else None) == before  # refused before writing anything


def test_placeholder_shows_the_papers_numbers(tmp_path, placeholder_table):
    rep = report(placeholder_table, tmp_path, results_root=tmp_path)
    assert len(rep["cells"]) == 28 and "PLACEHOLDER" in rep["caption"]
    md = (tmp_path / "reports" / f"{placeholder_table}-quick.md").read_text()
    assert f"{MISSING} \\| 0.47" in md
    tex = tmp_path / "reports" / "table4-quick.tex"
    report("table4", tmp_path, results_root=tmp_path)
    assert r"$<$known\_color$>$" in tex.read_text()  # \textless: a glyph of a font that needs cm-super


def test_an_experiments_caption_names_its_file_not_a_table_of_the_paper(tmp_path):
    """Issue 34's experiment is no table of the paper: its caption says what it is and how to run it, by the name
    `emml run` and a campaign step give it."""
    from emml.experiments.table_files import EXPERIMENTS_DIR

    none = tmp_path / "none"
    caption = report(str(EXPERIMENTS_DIR / "eqa_readout.toml"), tmp_path, results_root=none)["caption"]
    assert caption.startswith("Dual-Attention, Doom Easy, Aux: x_sent read from") and "Table" not in caption
    assert "`emml run experiments/eqa_readout --profile quick`" in caption  # as a campaign step names it
    assert report("table3", tmp_path, results_root=none)["caption"].startswith("Ours vs the paper's Table 3")
    assert sorted(p.name for p in (tmp_path / "reports").glob("eqa_readout-*")) == [
        "eqa_readout-quick.md",
        "eqa_readout-quick.tex",
    ]  # under its name in the reports folder, given its file's path
    md = (tmp_path / "reports" / "eqa_readout-quick.md").read_text()  # its rows' settings are not the paper's:
    assert "- x_sent read from the mean of the GRU's outputs (paper the GRU's last output" in md  # named
    table3 = (tmp_path / "reports" / "table3-quick.md").read_text()  # a paper table's ablations are its experiment
    said = table3.split("**Where the paper is silent**")[0].lower().splitlines()
    # (the No Aux warm-up's line names the rows it applies to, w/o Reward Shaping among them: issue 61)
    assert not any("reward shaping" in line for line in said if not line.startswith("- answer kept off"))
