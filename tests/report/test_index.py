"""reports/index.md: what a reader should read first, the experiments beyond the paper after its tables, and never
smoke numbers."""

from pathlib import Path

from emml.experiments.tables import load_table
from emml.report.index import profiles_with_results

GREEDY = ("sgn_train", "sgn_test", "eqa_train", "eqa_test")
"""The greedy metrics a recorded run's results row holds."""


def _recorded_easy_dual_attention(tmp_path, monkeypatch, roots: dict):
    """Table 2's Easy Dual-Attention runs of the demo profile, each recorded (a results row of 0.5 everywhere) under
    ``roots``, with a store of the test's own: yields each run's config."""
    from emml.config.profiles import profile_seeds
    from emml.runs.rundir import record_result

    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path}/mlflow.db")
    specs = [s for s in load_table("table2").runs(profile_seeds("demo")) if s.model == "dual_attention"]
    for spec in [s for s in specs if s.difficulty == "easy"]:
        cfg = spec.to_config("demo", **roots)
        payload = {"run_name": spec.run_name("demo"), "table": "table2", "model": cfg.model, "difficulty": "easy",
                   "aux": cfg.aux, "seed": 0, "profile": "demo", "frames": 64, "git_sha": "12e0077", "run_id": "x",
                   "eval_episodes": 1, "metrics": dict.fromkeys(GREEDY, 0.5)}  # fmt: skip
        record_result(payload, cfg)
        yield cfg


def test_quick_first_then_paper_then_the_rest_and_never_smoke(tmp_path):
    for table, profile in [("table2", "demo"), ("table2", "smoke"), ("table2", "paper"), ("table3", "quick")]:
        path = tmp_path / table / f"{profile}.csv"
        path.parent.mkdir(exist_ok=True)
        path.write_text("run_name\n")
    (tmp_path / "table2" / "quick.csv").write_text("run_name\n")
    for folder in ("eqa_readout", "mine"):  # issue 34's experiment is reported after the paper's tables; not a stray
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "quick.csv").write_text("run_name\n")
    assert profiles_with_results(tmp_path) == {
        "quick": ["table2", "table3", "eqa_readout"],
        "paper": ["table2"],
        "demo": ["table2"],
    }
    assert load_table("eqa_readout").rows[1].label == "mean"  # loadable by its name from here on


def test_a_damaged_run_dir_is_named_and_the_reports_go_on(tmp_path, monkeypatch, capsys):
    """Issue 54: a garbage results.json in a finished run dir killed `emml reports` with a JSON traceback naming no
    file, and no report was written. Now it is named, its run shown with its declared config, and the rest goes on;
    a checkpoint that cannot be read costs its figures only."""
    from emml.report.index import write_reports
    from emml.runs.rundir import CHECKPOINT, RESULTS, run_dir

    roots = {"run_root": str(tmp_path / "runs"), "results_root": str(tmp_path / "results")}
    damaged = None
    for cfg in _recorded_easy_dual_attention(tmp_path, monkeypatch, roots):
        if cfg.aux:
            damaged = run_dir(cfg)
            damaged.mkdir(parents=True)
            (damaged / RESULTS).write_text('{"run_name": "x", "config": {"model": ')  # a damaged file
            (damaged / CHECKPOINT).write_bytes(b"not a checkpoint")
    index = write_reports(tmp_path / "reports", roots["results_root"], roots["run_root"], log=print)
    text, out = index.read_text(), capsys.readouterr()
    assert "**table2** (2 runs, frames 64)" in text and (tmp_path / "reports" / "table2-demo.md").exists()
    assert f"note: {damaged / RESULTS}: not JSON (" in out.err  # named, once per reader, and the report written
    assert f"no figures of `{damaged.name}` here: checkpoint {damaged / CHECKPOINT}: not a PyTorch checkpoint" in text


def test_no_committed_report_names_a_folder_of_the_machine_that_wrote_it():
    """Committed reports are read on other machines: no absolute path of this checkout, a home or a temp folder."""
    from emml.config.paths import checkout_root
    from emml.runs.portable import portable, portable_uri

    here = str(checkout_root())
    for path in sorted((checkout_root() / "reports").glob("*.*")):
        if path.suffix not in (".md", ".tex", ".json", ".csv"):
            continue
        text = path.read_text(errors="replace")
        for machine in (here, "/tmp/", "/home/", "/root/"):
            assert machine not in text, f"{path.name} names {machine!r}"
    assert portable_uri(f"sqlite:///{here}/mlflow.db") == "sqlite:///mlflow.db"  # what the demo report prints
    assert portable(f"{here}/runs/demo/x") == "runs/demo/x"


def test_figures_are_named_by_table_and_run_so_tables_sharing_a_run_name_keep_both(tmp_path, monkeypatch):
    """Issue 60: Table 3 and Table 4 both have `dual_attention-easy-aux-sgnonly-s0-quick` (other vocabularies, other
    code); `channels-<run>.png` of one overwrote the other's. Each figure now names its table and its run."""
    from types import SimpleNamespace

    import emml.report.visualize as visualize
    import emml.runs.rundir as rundir
    from emml.report.index import figure_name, figures

    run = "dual_attention-easy-aux-sgnonly-s0-quick"
    drawn = {}

    def draw(table):
        def figure(*args, **kw):
            path = [a for a in (*args, *kw.values()) if isinstance(a, Path)][0]
            path.write_text(table)  # which table's run drew it

        return figure

    for table in ("table3", "table4"):
        cfg = SimpleNamespace(table=table, aux=True, env=SimpleNamespace(tasks="sgn", played=("sgn",)))
        monkeypatch.setattr(rundir, "load_model", lambda path, cfg=cfg: (None, cfg))
        monkeypatch.setattr(visualize, "channels_figure", draw(table))
        monkeypatch.setattr(visualize, "attention_figure", draw(table))
        monkeypatch.setattr(visualize, "record_episode", lambda *a: None)
        drawn[table] = figures(tmp_path / "runs" / table / run / "checkpoint.pt", tmp_path, seeds=(0,))
    assert [p.name for p in drawn["table3"]] == [f"channels-table3-{run}.png", f"attention-sgn-table3-{run}-s0.png"]
    assert [p.name for p in drawn["table4"]] == [f"channels-table4-{run}.png", f"attention-sgn-table4-{run}-s0.png"]
    assert all(p.read_text() == table for table, paths in drawn.items() for p in paths)  # neither overwritten
    assert figure_name("attention-eqa", "table2", "r", "-s1") == "attention-eqa-table2-r-s1.png"


def test_a_garbage_line_in_one_mirror_costs_that_run_only(tmp_path, monkeypatch, capsys):
    """Issue 65: one garbage line in one run's metrics.csv skipped the whole Table 2 page (its curves read the mirror)
    and, in a run a diagnostic claim reads, stopped `emml reports` with no file at all. Now that run's curve and
    cells are left out, it is named once with the line, and every other file is written."""
    from emml.report.index import write_reports
    from emml.runs.rundir import METRICS, run_dir

    roots = {"run_root": str(tmp_path / "runs"), "results_root": str(tmp_path / "results")}
    damaged = None
    for cfg in _recorded_easy_dual_attention(tmp_path, monkeypatch, roots):
        folder = run_dir(cfg)
        folder.mkdir(parents=True, exist_ok=True)
        lines = ["step,key,value"] + [f"{s},eval/{m},0.5" for s in (32, 64) for m in GREEDY]
        lines += [f"{s},diag/{k},0.8" for s in (32, 64) for k in ("attention_on_target", "detector_ap")]
        if cfg.aux:  # the run the claim 'attention-on-target' reads, and one of the table's curves
            damaged = folder / METRICS
            lines.insert(3, "garbage")
        (folder / METRICS).write_text("\n".join(lines) + "\n")
    index = write_reports(tmp_path / "reports", roots["results_root"], roots["run_root"], log=print)
    text, out = index.read_text(), capsys.readouterr()
    reports = tmp_path / "reports"
    for name in ("table2-demo.md", "table2-demo.tex", "table2-demo-curves.png", "claims-demo.md"):
        assert (reports / name).exists(), name
    assert "not reported" not in text and "not reported" not in out.out
    said = f"{damaged}: line 4: not a metric point"
    assert (out.err + out.out).count(said) == 1, out.err  # named once, with the line, for every reader of it


def test_the_index_counts_every_claim_those_shown_apart_named(tmp_path, monkeypatch):
    """The index's lead names every claim once: the counts of the reproduction's verdicts, then those shown apart
    (the paper's own table fails their rule: issue 81 item 4), so that its numbers add up to the claims it names."""
    from types import SimpleNamespace

    import emml.report.claims as claims
    from emml.report.index import claims_lines

    decisions = [SimpleNamespace(status=s, apart=a) for s, a in [("supported", False), ("supported", True)]]
    decisions += [SimpleNamespace(status="untestable yet", apart=False)]
    monkeypatch.setattr(claims, "campaign_costs", lambda: {})
    monkeypatch.setattr(claims, "write_claims", lambda *a, **k: (tmp_path / "claims-quick.md", decisions))
    (lead,) = [line for line in claims_lines({"quick": []}, tmp_path, tmp_path) if line]
    assert "3 claims" in lead and "1 supported, 1 untestable yet; 1 shown apart" in lead
