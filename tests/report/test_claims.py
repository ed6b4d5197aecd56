"""The claims page's decisions (emml/report/claims.py) in parts worked out by hand, no results read (issue 66:
mutation testing): the label with its seeds, the phrase per setting, the missing runs' costs, the counts."""

import math
from dataclasses import replace

from emml.config.profiles import resolve_profile
from emml.experiments.claims import load_claims
from emml.experiments.claims.evidence import HOLDS, MISSING, REVERSED, UNCLEAR, Chance, Check, Score
from emml.report.claims import BUDGET, ONE_SEED, SUPPORTED, UNTESTABLE, Decision, costs_of, paper_evidence
from emml.report.claims import _phrase as phrase


def decision(status: str, seeds: int = 0, **fields) -> Decision:
    return Decision("c", "text", "§5", "best", "table3", "quick", status, "", seeds=seeds, **fields)


def test_the_label_names_the_seeds_it_rests_on():
    assert decision(SUPPORTED, 1).label == "supported (on 1 seed)"
    assert decision(SUPPORTED, 3).label == "supported (on 3 seeds)"
    assert decision(UNTESTABLE).label == "untestable yet (no comparison yet)"
    assert decision(BUDGET).label == "not supported at this budget"
    assert decision(ONE_SEED, 1).label == "reversed on 1 seed"  # not '(on 1 seed)' twice


def test_each_missing_run_is_costed_under_its_own_table():
    d = decision(UNTESTABLE, missing=["a-s0-quick", "b-s1-quick (no sgn_train in its results row)"])
    d.owners = {"b-s1-quick": "table2"}
    costs = {("table3", "a-s0-quick"): "campaign step `t3`, pending: ~2.0 h here", ("table3", "b-s1-quick"): "no"}
    assert costs_of(d, costs) == [
        "`table3/a-s0-quick`: campaign step `t3`, pending: ~2.0 h here",
        "`table2/b-s1-quick`: in no step of the campaign",
    ]


def check(setting, outcome, what="SGN test, Easy · Aux: DA > GA", numbers="0.30 vs 0.50", chance=False, high=()):
    where, compared = what.split(": ", 1)  # the fixture's text as the page prints it: cells, then the comparison
    return Check(where, compared, outcome, "", chance, 1, list(high), numbers).tag(setting, "SGN test", "DA", ("DA",))


def test_the_phrase_counts_each_settings_comparisons_and_names_the_one_against():
    held = check("Easy · Aux", HOLDS, "SGN test, Easy · Aux: DA > FiLM", "0.90 vs 0.20")
    assert phrase([held, check("Easy · Aux", REVERSED)]) == (
        "Easy · Aux: 1 of 2 hold; reversed: SGN test DA > GA (0.30 vs 0.50)"
    )
    # a reversal of a row that learned goes before an excused one, which goes before one within the error
    excused = check("Easy · Aux", REVERSED, "SGN test, Easy · Aux: DA > Concat", "0.20 vs 0.40", chance=True)
    unclear = check("Easy · Aux", UNCLEAR, "SGN test, Easy · Aux: DA > PACMAN", "0.50 vs 0.52")
    assert phrase([unclear, excused, check("Easy · Aux", REVERSED)]).endswith(
        "reversed: SGN test DA > GA (0.30 vs 0.50)"
    )
    assert phrase([unclear, excused]) == (
        "Easy · Aux: 0 of 2 hold; reversed: SGN test DA > Concat (0.20 vs 0.40; DA has not learned)"
    )
    assert phrase([held, unclear]) == "Easy · Aux: 1 of 2 hold; unclear: SGN test DA > PACMAN (0.50 vs 0.52)"
    assert phrase([held, check("Easy · Aux", MISSING)]) == "Easy · Aux: 1 of 1 hold, 1 not run yet"
    # issue 81: a provisional reversal says so; a settled one, listed after it, is the one named
    provisional = check("Easy · Aux", REVERSED, "SGN test, Easy · Aux: DA > Concat", "0.30 vs 0.45")
    provisional.unsettled = "reversed on 1 seed"
    assert phrase([provisional]).endswith("; reversed on 1 seed: SGN test DA > Concat (0.30 vs 0.45)")
    assert phrase([provisional, check("Easy · Aux", REVERSED)]).endswith("; reversed: SGN test DA > GA (0.30 vs 0.50)")


def test_the_phrase_of_a_setting_with_nothing_run_says_who_has_not_learned():
    gone = check("Hard · Aux", MISSING)
    assert phrase([gone, gone]) == "Hard · Aux: 2 comparisons not run yet"
    unlearned = check(
        "Hard · No Aux", MISSING, chance=True, high=[Score("r", 0, 0.2, 100, 0), Score("r", 1, 0.3, 100, 0)]
    )
    assert phrase([gone, unlearned]) == (
        "Hard · Aux: 1 comparison not run yet; Hard · No Aux: DA has not learned (SGN test 0.25), 1 comparison not run "
        "yet"
    )
    # a missing comparison whose higher row is there and learned excuses nothing
    assert phrase([check("Hard · Aux", MISSING, high=[Score("r", 0, 0.9, 100, 0)])]) == (
        "Hard · Aux: 1 comparison not run yet"
    )
    eqa = replace(unlearned, metric="EQA test", high=[Score("r", 0, 0.5, 100, 0)])
    assert phrase([unlearned, eqa]) == (
        "Hard · No Aux: DA has not learned (SGN test 0.25, EQA test 0.50), 2 comparisons not run yet"
    )


def test_every_claim_is_decided_with_the_one_blind_prior_of_the_results_read(monkeypatch):
    """decide_all: the prior read once from the profile's results under the root given, then each claim of
    reproduce/claims.toml, in the file's order, decided from the same results and run dirs with that prior; with
    `costs`, each decision's missing runs costed."""
    import emml.report.claims as claims

    prior, asked, decided = Chance({("easy", "eqa_test"): 0.4}), [], []
    monkeypatch.setattr(claims, "blind_prior", lambda profile, root=None: asked.append((profile.name, root)) or prior)

    def decide(claim, profile, results_root=None, run_root=None, chance=None, plans=None):
        decided.append((claim.id, profile.name, results_root, run_root, chance))  # the profile resolved once
        return decision(UNTESTABLE, missing=[f"{claim.id}-s0-quick"])

    monkeypatch.setattr(claims, "decide", decide)
    ids = list(load_claims())
    out = claims.decide_all("quick", "RESULTS", {("table3", f"{ids[0]}-s0-quick"): "step `s`"}, "RUNS")
    assert asked == [("quick", "RESULTS")]
    assert decided == [(i, "quick", "RESULTS", "RUNS", prior) for i in ids]
    assert [d.costs for d in out[:2]] == [
        [f"`table3/{ids[0]}-s0-quick`: step `s`"],
        [f"`table3/{ids[1]}-s0-quick`: in no step of the campaign"],
    ]
    assert claims.decide_all("quick", "RESULTS", None, "RUNS")[0].costs == []


def test_the_page_is_written_from_the_decisions_of_the_results_given(tmp_path, monkeypatch):
    """write_claims: the decisions of the results, run dirs and costs given, the paper's own for every claim, the
    page in a folder made for it (`out`, parents and all) as claims-<profile>.md."""
    import emml.report.claims as claims
    import emml.report.claims_page as page
    import emml.report.eqa_test as eqa

    prior, got = Chance({("easy", "eqa_test"): 0.4}), {}
    monkeypatch.setattr(claims, "blind_prior", lambda profile, root=None: prior if root == "RESULTS" else None)
    monkeypatch.setattr(claims, "decide_all", lambda *args: got.setdefault("decide_all", args) and ["decided"])
    monkeypatch.setattr(claims, "decide_paper", lambda claim: f"paper {claim.id}")
    found = {"table2"}  # the tables with a finished run of the results given
    monkeypatch.setattr(claims, "_tables_with_runs", lambda names, profile, root: found if root == "RESULTS" else set())

    def pages(folder, *args):  # emml/report/claims_page.py writes the page, its detail and its figure
        got["pages"] = (folder, *args)
        (folder / "claims-quick.md").write_text("PAGE\n")
        return [folder / "claims-quick.md", folder / "claims-quick-detail.md"]

    monkeypatch.setattr(page, "write_pages", pages)
    monkeypatch.setattr(
        eqa, "read_arms", lambda profile, root, run_root=None: got.setdefault("arms", (profile.name, root)) and []
    )
    monkeypatch.setattr(
        eqa, "finding", lambda arms, paper, chance, profile, figure=None: ["EQA", arms, paper, chance, profile, figure]
    )
    out = tmp_path / "a" / "b"
    path, decisions = claims.write_claims("quick", out, "RESULTS", {"k": "v"}, "RUNS")
    assert path == out / "claims-quick.md" and path.read_text() == "PAGE\n" and decisions == ["decided"]
    assert got["decide_all"] == (resolve_profile("quick"), "RESULTS", {"k": "v"}, "RUNS")
    ids = list(load_claims())
    folder, decided, profile, paper, loaded, chance, tables, findings = got["pages"]
    assert (folder, decided, profile.name, paper) == (out, ["decided"], "quick", {i: f"paper {i}" for i in ids})
    assert list(loaded) == ids and chance == prior and tables == {"table2"}
    # issue 62's finding, from the results given and the same blind prior, at the paper's 0.58
    assert got["arms"] == ("quick", "RESULTS") and findings == ["EQA", [], 0.58, prior, "quick", None]


def test_the_campaign_costs_each_unfinished_run_by_its_step(monkeypatch):
    """campaign_costs: (table, run) → its step, state and the hours left here and on a GPU node; finished runs left
    out; {} when the campaign cannot be read."""
    from types import SimpleNamespace as Row

    import emml.experiments.campaign as campaign
    from emml.report.claims import campaign_costs

    rows = [
        Row(table="table2", run_name="b", step="s1", state="done", seconds_left=0, node_seconds_left=0),
        Row(table="table2", run_name="a", step="s1", state="pending", seconds_left=5580, node_seconds_left=1620),
        Row(table="table3", run_name="a", step="s2", state="running", seconds_left=0, node_seconds_left=0),
    ]
    asked = []
    monkeypatch.setattr(campaign, "load_campaign", lambda name: asked.append(name) or "loaded")
    monkeypatch.setattr(campaign, "status", lambda c: rows if c == "loaded" else [])
    assert campaign_costs("mine") == {
        ("table2", "a"): "campaign step `s1`, pending: ~1.6 h here, ~0.5 h on a GPU node",  # 1.55 h, 0.45 h
        ("table3", "a"): "campaign step `s2`, running: no estimate here",
    }
    assert asked == ["mine"] and campaign_costs() and asked[-1] == "reference"

    def unreadable(name):
        raise ValueError("no such campaign")

    monkeypatch.setattr(campaign, "load_campaign", unreadable)
    assert campaign_costs() == {}


def test_the_paper_evidence_reads_the_claims_rows_with_the_chance_given():
    """reproduce/paper/table2.csv: GA 0.24 and Text only 0.33 on EQA test, Easy · Aux. Each number one seed of 500
    episodes, its own training score; the bar the training split's chance + 0.1 (0.5 given: 0.6; the test split's
    0.7 is not read), none for the blind row."""
    claims = load_claims()
    chance = Chance({("easy", "eqa_train"): 0.5, ("easy", "eqa_test"): 0.7})
    ev = paper_evidence(replace(claims["baselines-below-text-only-eqa"], rows=("GA",)), chance)
    assert (
        sorted(ev.scores) == [(row, "easy", aux, "eqa_test") for row in ("GA", "Text only") for aux in (False, True)]
        and not ev.missing
    )
    (ga,) = ev.scores[("GA", "easy", True, "eqa_test")]
    assert (ga.run, ga.seed, ga.value, ga.episodes, ga.train, ga.bar) == ("the paper's table", 0, 0.24, 500, 0.24, 0.6)
    (blind,) = ev.scores[("Text only", "easy", True, "eqa_test")]
    assert (blind.value, blind.bar) == (0.33, -math.inf)
    assert ga.frames == 0  # the paper gives no frames per cell
    (entry,) = [e for e in ev.evidence if e["row"] == "GA" and e["setting"] == "Easy · Aux"]
    assert entry == {
        "row": "GA",
        "setting": "Easy · Aux",
        "metric": "EQA test",
        "values": {0: 0.24},
        "shown": {0: "0.24"},
        "declared": 1,
    }
    # a training column: the paper prints none, so each cell is missing
    train = paper_evidence(claims["da-best-hard-train"])
    assert train.scores[("Dual-Attention", "hard", True, "sgn_train")] == []
    assert "Dual-Attention, Hard · Aux, SGN train (no number)" in train.missing
    (entry,) = [
        e
        for e in train.evidence
        if (e["row"], e["setting"], e["metric"]) == ("Dual-Attention", "Hard · Aux", "SGN train")
    ]
    assert (entry["values"], entry["shown"], entry["declared"]) == ({}, {}, 1)


def test_every_claim_is_decided_with_each_table_planned_once(monkeypatch):
    """decide_all plans a table once for all of its claims (each plan names every run of the table)."""
    import emml.report.claims as claims

    planned = []
    real = claims.plan_report
    monkeypatch.setattr(claims, "plan_report", lambda table, *a: planned.append(table) or real(table, *a))
    decisions = claims.decide_all("quick", "RESULTS-NOWHERE", run_root="RUNS-NOWHERE")
    assert len(decisions) == len(load_claims())
    assert sorted(planned) == sorted({c.table for c in load_claims().values()})
