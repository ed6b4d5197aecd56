"""The claims page (emml/report/claims.py, issue 49) on a FIXTURE of made-up results rows in tmp_path (never
results): a claim flips when a results row changes; the binomial error, missing cells, chance and the seed count
decide as the page's rules say; the page is the same bytes twice."""

import pandas as pd

from emml.config.profiles import profile_seeds
from emml.experiments.claims import load_claims
from emml.experiments.claims.evidence import STATUSES
from emml.experiments.tables import load_table
from emml.report.claims import (
    BUDGET,
    CONTRADICTED,
    INCONCLUSIVE,
    SUPPORTED,
    UNKNOWN_FLAT,
    UNTESTABLE,
    decide,
    write_claims,
)
from emml.report.claims_page import counts
from tests.report.test_claims import decision
from tests.report.test_tables import PROFILE, fake_results

CLAIMS = load_claims()


def da_ahead(spec):
    """Dual-Attention 0.5 / 0.6 / 0.7 over seeds 0-2, every other row 0.1 / 0.2 / 0.3."""
    return 0.5 + 0.1 * spec.seed if spec.model == "dual_attention" else 0.1 * (spec.seed + 1)


def edit(root, table: str, run: str, **values) -> None:
    """Change one results row of the fixture, as a rescored run would."""
    path = root / table / f"{PROFILE}.csv"
    df = pd.read_csv(path)
    for column, value in values.items():
        df.loc[df["run_name"] == run, column] = value
    df.to_csv(path, index=False)


def flat(tmp_path, table: str = "table2"):
    """FIXTURE: every declared run of ``table`` a flat curve (0.2 at each of 10 evaluations) under tmp_path/runs:
    a reversal read on them is not closing, so three seeds settle it."""
    from emml.report.plan import plan_report

    runs = tmp_path / "runs"
    for run in plan_report(table, PROFILE).runs:  # every planned run, a row's more_seeds too
        folder = runs / run.spec.table / run.name
        folder.mkdir(parents=True, exist_ok=True)
        frames = run.cfg.frames
        lines = ["step,key,value"] + [
            f"{frames * i // 10},eval/{m},0.2"
            for i in range(1, 11)
            for m in ("sgn_train", "sgn_test", "eqa_train", "eqa_test")
        ]
        (folder / "metrics.csv").write_text("\n".join(lines) + "\n")
    return runs


def test_a_claim_flips_when_a_results_row_changes(tmp_path):
    root = tmp_path / "results"
    fake_results("table2", root, value=da_ahead)
    claim = CLAIMS["da-best-easy-aux"]
    d = decide(claim, PROFILE, root)
    assert d.status == SUPPORTED and d.label == f"{SUPPORTED} (on 3 seeds)" and d.seeds == 3 and not d.missing
    edit(root, "table2", "text_only-easy-aux-s1-quick", eqa_test=0.95)  # one seed of one baseline ahead
    d = decide(claim, PROFILE, root)
    assert d.status == INCONCLUSIVE and "Text only" in d.phrase  # 0.6 against 0.45 over seeds 0.1 / 0.95 / 0.3: unclear
    for seed in (0, 2):
        edit(root, "table2", f"text_only-easy-aux-s{seed}-quick", eqa_test=0.95)  # now ahead in every seed
    d = decide(claim, PROFILE, root)  # three seeds each, but no curve here: flatness unknown
    assert d.status == UNKNOWN_FLAT and f"{UNKNOWN_FLAT}: EQA test Dual-Attention > Text only" in d.phrase
    d = decide(claim, PROFILE, root, flat(tmp_path))  # flat curves: settled
    assert d.status == CONTRADICTED and "reversed: EQA test Dual-Attention > Text only" in d.phrase


def test_missing_cells_are_untestable_and_name_their_runs(tmp_path):
    root = tmp_path / "results"
    fake_results("table2", root, value=da_ahead, drop=("pacman-hard-aux-s0-quick", "pacman-hard-aux-s1-quick"))
    d = decide(CLAIMS["da-best-hard-aux"], PROFILE, root)
    assert d.status == SUPPORTED  # PACMAN's seed 2 is there: compared on it
    fake_results(
        "table2", tmp_path / "r2", value=da_ahead, drop=tuple(f"pacman-hard-aux-s{s}-quick" for s in (0, 1, 2))
    )
    d = decide(CLAIMS["da-best-hard-aux"], PROFILE, tmp_path / "r2")
    assert d.status == UNTESTABLE and d.missing == [f"pacman-hard-aux-s{s}-quick" for s in (0, 1, 2)]


def test_a_row_at_chance_is_not_supported_at_this_budget_and_one_seed_says_so(tmp_path):
    root = tmp_path / "results"

    def da_at_chance(spec):  # Dual-Attention at SGN chance, below a baseline: it has not learned
        return 0.2 if spec.model == "dual_attention" else 0.25

    runs = load_table("table2").runs(profile_seeds(PROFILE))
    drop = [
        s.run_name(PROFILE)
        for s in runs
        if s.model in ("dual_attention", "ga") and s.difficulty == "easy" and not s.aux and s.seed in (1, 2)
    ]
    fake_results("table2", root, value=da_at_chance, drop=tuple(drop))
    d = decide(CLAIMS["da-best-easy-noaux"], PROFILE, root)
    assert d.status == BUDGET and "has not learned" in d.phrase  # its SGN train 0.2, the blind row's 0.25 + 0.1
    assert d.label == f"{BUDGET} (on 1 seed)"


def test_a_train_claim_reads_the_train_columns_of_the_same_runs(tmp_path):
    """'da-best-hard-train' reads sgn_train / eqa_train from the Hard rows: a baseline ahead on train only flips it,
    whatever the test columns say."""
    root = tmp_path / "results"
    fake_results("table2", root, value=da_ahead)
    claim = CLAIMS["da-best-hard-train"]
    assert decide(claim, PROFILE, root).status == SUPPORTED
    for seed in (0, 1, 2):
        edit(root, "table2", f"concat-hard-aux-s{seed}-quick", sgn_train=0.99)
    d = decide(claim, PROFILE, root, flat(tmp_path))
    assert d.status == CONTRADICTED and "SGN train Dual-Attention > Concat" in d.phrase
    assert decide(CLAIMS["da-best-hard-aux"], PROFILE, root).status == SUPPORTED  # the test columns did not move


def test_eqa_harder_counts_the_rows_where_eqa_is_below_sgn(tmp_path):
    """The paper's "most models", each task above its own chance (SGN 0.2, EQA 0.5 here: (s − c) / (1 − c)): 4 of 7
    rows with EQA below SGN holds, 3 of 7 does not; a row missing waits; rows reversed in rows that learned their
    SGN training split contradict it once settled (flat curves); excused only when most rows did not."""
    from emml.experiments.claims.evidence import Chance

    chance = Chance({(d, m): v for d in ("easy", "hard") for m, v in (("sgn_test", 0.2), ("eqa_test", 0.5))}, "made up")
    root = tmp_path / "results"
    runs = flat(tmp_path)
    lower = {"dual_attention", "concat", "ga", "film"}

    def split(spec):  # SGN 0.8 for the four (0.75 above chance), 0.6 for the rest (0.5)
        return 0.8 if spec.model in lower else 0.6

    fake_results("table2", root, value=split)
    path = root / "table2" / f"{PROFILE}.csv"
    df = pd.read_csv(path)
    df["eqa_test"] = [0.5 if m in lower else 0.9 for m in df["model"]]  # above chance 0 for the four, 0.8 the rest
    df.to_csv(path, index=False)
    claim = CLAIMS["eqa-harder"]
    d = decide(claim, PROFILE, root, runs, chance)
    assert d.status == SUPPORTED and "in 4 of 7 rows" in d.checks[0].numbers
    for seed in (0, 1, 2):  # FiLM level: 0.875 is 0.75 above chance, as its SGN: 3 hold, 3 reversed in Easy · Aux
        edit(root, "table2", f"film-easy-aux-s{seed}-quick", eqa_test=0.875)
    d = decide(claim, PROFILE, root, runs, chance)
    assert d.status == INCONCLUSIVE and "in 3 of 7 rows" in d.phrase  # neither most hold nor most reversed
    for m in ("concat", "ga"):
        for seed in (0, 1, 2):
            edit(root, "table2", f"{m}-easy-aux-s{seed}-quick", eqa_test=0.99)  # 0.98 above chance against 0.75
    assert decide(claim, PROFILE, root, chance=chance).status == UNKNOWN_FLAT  # no curve: flatness unknown
    d = decide(claim, PROFILE, root, runs, chance)
    assert d.status == CONTRADICTED  # 5 of 7 reversed (Concat, GA, PACMAN, Text only, Image only), SGN learned
    for m in ("concat", "ga", "film", "pacman", "text_only"):
        for seed in (0, 1, 2):
            edit(root, "table2", f"{m}-easy-aux-s{seed}-quick", eqa_test=0.9, sgn_test=0.2)
    # issue 60: at SGN chance on test but learned on their training split: the reversal counts
    assert decide(claim, PROFILE, root, runs, chance).status == CONTRADICTED
    for m in ("concat", "ga", "film", "pacman", "text_only"):
        for seed in (0, 1, 2):
            edit(root, "table2", f"{m}-easy-aux-s{seed}-quick", sgn_train=0.2)
    assert decide(claim, PROFILE, root, runs, chance).status == BUDGET  # most rows have not learned their training
    runs = load_table("table2").runs(profile_seeds(PROFILE))
    every = tuple(s.run_name(PROFILE) for s in runs if s.model == "ga" and s.difficulty == "hard" and not s.aux)
    fake_results("table2", tmp_path / "r2", value=split, drop=every)  # GA Hard No Aux: no run in any seed
    d = decide(claim, PROFILE, tmp_path / "r2")
    hard = [c for c in d.checks if c.setting == "Hard · No Aux"]
    assert d.status == UNTESTABLE and hard[0].outcome == "missing" and "no run yet for GA" in hard[0].detail


def test_the_page_leads_with_a_line_per_claim_and_is_the_same_bytes_twice(tmp_path):
    """Issue 63: the page read first is the status table (status, seeds, the paper's numbers and ours) and the
    figure; the rules and the sections per claim are in the detail page it links."""
    root = tmp_path / "results"
    for table in ("table2", "table3"):
        fake_results(table, root, value=da_ahead)
    path, decisions = write_claims(PROFILE, tmp_path / "reports", root)
    text = path.read_text()
    detail = (tmp_path / "reports" / "claims-quick-detail.md").read_text()
    assert path.name == "claims-quick.md" and len(decisions) == len(CLAIMS)
    lines = text.split("\n")
    assert lines[4] == "| Claim | Status | Seeds | Cells (focus rows) | Paper | Ours | On the paper's table |"
    apart = [d.id for d in decisions if d.apart]
    assert apart == [c for c in CLAIMS if CLAIMS[c].on_paper]  # the paper's own table fails them: shown apart
    counted = [c for c in CLAIMS if c not in apart]
    table = lines[6 : 6 + len(counted)]
    for claim, line in zip(counted, table):
        assert line.startswith(f"| [{claim}](claims-quick-detail.md#{claim}) |")
    by_id = dict(zip(counted, table))
    assert "**The paper's table does not support its text**" in text
    assert "shown apart (the paper's table does not support its text)" in lines[2]
    for claim in apart:  # below the counted table, not in it
        assert f"| [{claim}](claims-quick-detail.md#{claim}) |" in text.split("does not support its text**")[1]
    # Dual-Attention 0.7 (mean of 0.5 … 0.9, its five seeds: more_seeds 3-4) against the paper's 0.96 / 0.58
    row = "| supported (12 of 12 hold) | Dual-Attention 5 | SGN test<br>EQA test | 0.96<br>0.58 | 0.70<br>0.70 | "
    assert row in by_id["da-best-easy-aux"]
    assert "![Ours against the paper, per claim](claims-quick.png)" in text
    assert "## Decision rules" not in text and "Welch" not in text and len(text) < len(detail) / 2
    assert "**fails**" in text  # aux-helps fails on the paper's own table
    for name in ("claims-quick.png", "claims-quick.pdf"):
        assert (tmp_path / "reports" / name).stat().st_size > 0
    assert "## Decision rules" in detail and "Welch" in detail
    for claim in CLAIMS:
        assert f'<a id="{claim}"></a>' in detail and f"| [{claim}](#{claim}) |" in detail
    assert "Not a sentence of the paper: inferred from its Table 3." in detail  # multitask-helps
    # Table 5 has no run here: its claim names it without a link to a page that is not written (issue 63)
    assert "table5-quick.md" not in detail and "Table 5 (no page at this profile" in detail
    assert "[table2-quick.md](table2-quick.md)" in detail
    first = {p.name: p.read_bytes() for p in (tmp_path / "reports").iterdir()}
    write_claims(PROFILE, tmp_path / "reports", root)
    assert {p.name: p.read_bytes() for p in (tmp_path / "reports").iterdir()} == first


def test_the_figure_is_print_width_and_no_text_leaves_its_canvas(tmp_path, monkeypatch):
    """Issue 63: the claims figure at 7 in across, every text (tick labels, legend, title, notes) inside the
    canvas."""
    import matplotlib.pyplot as plt

    import emml.report.claims_page as page

    root = tmp_path / "results"
    fake_results("table2", root, value=da_ahead)
    drawn = []
    monkeypatch.setattr(plt, "close", lambda fig=None: drawn.append(fig))
    write_claims(PROFILE, tmp_path / "reports", root)
    figs = [f for f in drawn if f is not None]  # the claims figure, and the EQA box's gate figure where drawn
    (claims_fig,) = [f for f in figs if any(a.get_title().startswith("Ours against the paper") for a in f.axes)]
    for fig in figs:
        assert tuple(fig.get_size_inches())[0] == page.FIGURE_WIDTH
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        canvas = fig.bbox
        texts = [t for t in fig.findobj(plt.Text) if t.get_visible() and t.get_text()]
        assert fig is not claims_fig or len(texts) > len(CLAIMS)
        for t in texts:
            box = t.get_window_extent(renderer)
            assert box.x0 >= -1 and box.y0 >= -1 and box.x1 <= canvas.x1 + 1 and box.y1 <= canvas.y1 + 1, t.get_text()
    pdf = (tmp_path / "reports" / "claims-quick.pdf").read_bytes()
    assert b"/MediaBox [ 0 0 504 " in pdf  # 7 in = 504 pt


def test_missing_runs_are_costed_by_their_own_table():
    """Issue 60: Tables 3 and 4 both have `dual_attention-easy-aux-sgnonly-s1-quick`; a Table 4 claim's missing run
    is costed to the step that trains Table 4's, and Table 3's DA Multi-Task to Table 2's (it borrows its runs)."""
    from emml.report.claims import Decision, costs_of

    name = "dual_attention-easy-aux-sgnonly-s1-quick"
    costs = {("table3", name): "campaign step `table3-seeds-1-2`", ("table4", name): "campaign step `table4-easy`"}
    d = Decision("transfer-easy", "t", "s", "at_least", "table4", PROFILE, UNTESTABLE, "", missing=[name])
    assert costs_of(d, costs) == [f"`table4/{name}`: campaign step `table4-easy`"]
    d.owners = {name: "table3"}
    assert costs_of(d, costs) == [f"`table3/{name}`: campaign step `table3-seeds-1-2`"]
    d.missing = ["ga-easy-aux-s1-quick (no sgn_train in its results row)"]
    assert costs_of(d, costs) == ["`table4/ga-easy-aux-s1-quick`: in no step of the campaign"]


def test_every_status_names_its_seed_count():
    from emml.report.claims import Decision

    d = Decision("x", "t", "s", "best", "table2", PROFILE, BUDGET, "", seeds=1)
    assert d.label == f"{BUDGET} (on 1 seed)"
    d.seeds, d.status = 3, SUPPORTED
    assert d.label == f"{SUPPORTED} (on 3 seeds)"
    d.seeds, d.status = 0, UNTESTABLE
    assert d.label == f"{UNTESTABLE} (no comparison yet)"


def test_the_blind_row_is_never_excused_as_unlearned(tmp_path):
    """'Every baseline below Text only on EQA test': Text only is the chance line itself, so its training score at
    chance (0.38, its own) excuses nothing: baselines above it contradict the claim."""
    root = tmp_path / "results"
    fake_results("table2", root, value=lambda spec: 0.45 if spec.model == "text_only" else 0.6)
    for spec in load_table("table2").runs(profile_seeds(PROFILE)):
        if spec.model == "text_only":
            edit(root, "table2", spec.run_name(PROFILE), eqa_train=0.38)
    d = decide(CLAIMS["baselines-below-text-only-eqa"], PROFILE, root, flat(tmp_path))
    assert d.status == CONTRADICTED, d.phrase


def test_the_counts_cover_every_status():
    assert counts([decision(SUPPORTED), decision(BUDGET), decision(SUPPORTED)]) == {
        s: {SUPPORTED: 2, BUDGET: 1}.get(s, 0) for s in STATUSES
    }


def test_a_claim_the_paper_own_table_fails_is_not_counted_but_named_apart():
    from emml.report.claims_page import tally

    apart = decision(CONTRADICTED, apart=True)
    assert counts([decision(SUPPORTED), apart]) == {s: {SUPPORTED: 1}.get(s, 0) for s in STATUSES}
    assert tally([decision(SUPPORTED), apart]).endswith("; 1 shown apart (the paper's table does not support its text)")
    assert "shown apart" not in tally([decision(SUPPORTED)])


def test_a_claim_not_supported_shows_the_rows_of_the_comparison_against_it(tmp_path):
    """The status table's focus rows gain the rows of the first comparison that goes against the claim (reversed
    before unclear): 'contradicted' beside the paper's number and ours on Dual-Attention alone would hide the row that
    contradicts it. A supported claim shows its focus rows only."""
    from emml.experiments.claims.evidence import Check
    from emml.report.claims_page import against, cells, focus_rows

    def checks(*triples):
        return [Check(*what.split(": ", 1), outcome, "", rows=rows) for what, outcome, rows in triples]

    evidence = [{"row": r} for r in ("Dual-Attention", "Concat", "GA", "Go to the red <known_object>")]
    d = decision(CONTRADICTED, 1, evidence=evidence, checks=checks(
        ("SGN test, Easy · Aux: Dual-Attention > GA", "unclear", ("Dual-Attention", "GA")),
        ("EQA test, Hard · Aux: Dual-Attention > Concat", "reversed", ("Dual-Attention", "Concat")),
    ))  # fmt: skip
    assert against(d) == ["Dual-Attention", "Concat"]  # the reversed one, though the unclear one comes first
    d.checks = checks(
        ("SGN test, Easy · Aux: Dual-Attention > GA", "unclear", ("Dual-Attention", "GA")),
        ("x: Dual-Attention > Concat", "holds", ("Dual-Attention", "Concat")),
    )
    assert against(d) == ["Dual-Attention", "GA"]
    d.checks = checks(
        ("SGN, Easy · Aux: Go to the red <known_object> ≥ 0.8", "reversed", ("Go to the red <known_object>",))
    )
    assert against(d) == ["Go to the red <known_object>"]
    d.checks = checks(("Easy · Aux: EQA test below SGN test", "reversed", ()))  # 'harder': most rows, none named
    assert against(d) == []
    d.checks = checks(("SGN test, Easy · Aux: Concat level with GA", "reversed", ("GA", "Concat")))
    assert against(d) == ["GA", "Concat"]
    d.status = SUPPORTED
    assert against(d) == []
    d.status = INCONCLUSIVE
    assert against(d) == ["GA", "Concat"]

    root = tmp_path / "results"
    fake_results("table2", root, value=da_ahead)
    claim = CLAIMS["da-best-easy-aux"]
    supported = decide(claim, PROFILE, root)
    assert focus_rows(claim, supported) == ["Dual-Attention"]
    assert [c.label for c in cells(supported, None, claim)] == ["SGN test", "EQA test"]
    for seed in (0, 1, 2):  # Text only ahead on EQA in every seed, flat curves: contradicted
        edit(root, "table2", f"text_only-easy-aux-s{seed}-quick", eqa_test=0.95)
    d = decide(claim, PROFILE, root, flat(tmp_path))
    assert d.status == CONTRADICTED and focus_rows(claim, d) == ["Dual-Attention", "Text only"]
    assert [(c.label, c.shown) for c in cells(d, None, claim)] == [  # the deciding comparison's cells first
        ("Dual-Attention, EQA test", "0.70"),
        ("Text only, EQA test", "0.95"),
        ("Dual-Attention, SGN test", "0.70"),
        ("Text only, SGN test", "0.20"),
    ]


def test_the_deciding_comparison_is_a_settled_reversal_before_a_provisional_one_and_most_names_its_row():
    """Issue 81 item 5: the first screen shows the rows of the comparison that decides: a settled reversal (what
    makes the claim contradicted) before a provisional one listed first; a 'most' reversal names its first reversed
    row; the deciding rows lead the focus rows."""
    from emml.experiments.claims.evidence import ONE_SEED, Check
    from emml.report.claims_page import against, deciding, focus_rows

    one_seed = Check("SGN test, Easy · Aux", "Dual-Attention > GA", "reversed", "", rows=("Dual-Attention", "GA"))
    one_seed.unsettled = ONE_SEED
    settled = Check(
        "EQA test, Easy · Aux", "Dual-Attention > Concat", "reversed", "", rows=("Dual-Attention", "Concat")
    )
    d = decision(CONTRADICTED, 1, checks=[one_seed, settled])
    assert deciding(d) is settled and against(d) == ["Dual-Attention", "Concat"]
    d.checks = [one_seed]
    assert against(d) == ["Dual-Attention", "GA"]
    held = Check("Text only", "SGN test > EQA test", "holds", "", rows=("Text only",))
    lost = Check("Concat", "SGN test > EQA test", "reversed", "", rows=("Concat",))
    d.checks = [Check("Easy · Aux", "EQA test below SGN test", "reversed", "", parts=[held, lost])]
    assert against(d) == ["Concat"]
    assert focus_rows(CLAIMS["baselines-below-text-only-eqa"], d) == ["Concat", "Text only", "Image only"]


def test_seeds_are_per_row_and_the_status_counts_what_holds():
    """'Dual-Attention 3 · Text only 1', not the fewest; a row whose cells differ shows the range; a claim with
    several comparisons says how many hold."""
    from emml.experiments.claims.evidence import Check
    from emml.report.claims_page import row_seeds, status_text

    evidence = [
        {"row": "Dual-Attention", "values": {0: 0.5, 1: 0.6, 2: 0.7}},
        {"row": "Dual-Attention", "values": {0: 0.5, 1: 0.6}},
        {"row": "Text only", "values": {0: 0.4}},
        {"row": "GA", "values": {}},
    ]
    d = decision(CONTRADICTED, 1, evidence=evidence)
    assert row_seeds(d, ["Dual-Attention", "Text only", "GA"]) == "Dual-Attention 2–3 · Text only 1"
    d.checks = [Check("w", "x", o, "") for o in ("holds",) * 14 + ("reversed", "missing")]
    assert status_text(d) == f"{CONTRADICTED} (14 of 15 hold)"
    d.checks = d.checks[-2:-1]
    assert status_text(d) == CONTRADICTED  # one comparison: nothing to count


def test_a_no_aux_cell_under_the_warm_up_says_so_with_the_paper_literal_run_beside_it():
    """Issue 81 item 5: the No Aux column's runs are …-noaux-warm400000-…: its cell says 'warm-up 400k', and the
    paper-literal Dual-Attention No Aux run (no warm-up) is shown beside it with its own number; an Aux cell is
    labelled as it was."""
    from emml.report.claims_page import cells

    def entry(setting, runs, value):
        return {"row": "Dual-Attention", "setting": setting, "metric": "SGN test", "values": {0: value},
                "shown": {0: f"{value:.3f}"}, "runs": runs, "column": "sgn_test"}  # fmt: skip

    d = decision(SUPPORTED, 1, evidence=[
        entry("Easy · No Aux", ["dual_attention-easy-noaux-warm400000-s0-quick"], 0.52),
        entry("Easy · Aux", ["dual_attention-easy-aux-s0-quick"], 0.92),
    ])  # fmt: skip
    d.literal = [{"row": "Dual-Attention", "setting": "Easy · No Aux", "metric": "SGN test",
                  "run": "table2/dual_attention-easy-noaux-s0-quick", "value": 0.194}]  # fmt: skip
    claim = CLAIMS["da-best-easy-noaux"]
    assert [(c.label, c.shown) for c in cells(d, None, claim)] == [
        ("Easy · No Aux (warm-up 400k), SGN test", "0.52"),
        ("Easy · No Aux (no warm-up, the paper's loss: table2/dual_attention-easy-noaux-s0-quick), SGN test", "0.19"),
        ("Easy · Aux, SGN test", "0.92"),
    ]  # fmt: skip
