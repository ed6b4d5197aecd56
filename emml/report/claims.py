"""The claims page (issues 49 and 60): each claim of reproduce/claims.toml decided from a profile's results, and
from the paper's own tables by the same rules, with the numbers per row and seed that decide it, the runs still
missing and, where the campaign knows them, the step that trains each and what it costs.

The evidence is gathered here (`gather`: a profile's results rows and run dirs; `paper_evidence`: the paper's
numbers as one seed of PAPER_EPISODES episodes); the kinds weigh it (emml/experiments/claims/kinds.py, rules in
emml/experiments/claims/evidence.py); the page is written by emml/report/claims_page.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from emml.config.profiles import Profile, resolve_profile
from emml.eval.metrics import train_of
from emml.experiments.claims.evidence import (
    BUDGET,
    CLOSING,
    CONTRADICTED,
    HOLDS,
    INCONCLUSIVE,
    MISSING,
    ONE_SEED,
    REVERSED,
    SUPPORTED,
    UNKNOWN_FLAT,
    UNTESTABLE,
    Chance,
    Check,
    Score,
    mean,
    status,
    task_of,
)
from emml.report.chance import BLIND_MODEL, blind_prior, paper_prior
from emml.report.claims_reading import Reading
from emml.report.claims_settle import Curves, borrow, isnan, literal, next_seed, settle_all, settle_costs, spreads
from emml.report.plan import ReportPlan, plan_report

__all__ = [
    "BUDGET",
    "CLOSING",
    "CONTRADICTED",
    "ONE_SEED",
    "UNKNOWN_FLAT",
    "INCONCLUSIVE",
    "SUPPORTED",
    "UNTESTABLE",
    "Decision",
    "decide",
    "decide_paper",
    "decide_all",
]
PAPER_EPISODES = 500
"""The episodes a paper number is read as the success rate of: the paper gives no count (docs/fidelity.md); ours,
the final evaluation's 500 per task and split."""
PAPER = "the paper's table"


@dataclass
class Decision:
    """A claim decided from one source (a profile's results, or the paper's own table)."""

    id: str
    text: str
    source: str
    kind: str
    table: str
    profile: str
    status: str
    phrase: str
    """The evidence in a phrase (the page's top block)."""
    checks: list[Check] = field(default_factory=list)
    evidence: list[dict] = field(default_factory=list)
    """One line per row and cell: row, setting, metric, each seed's value."""
    missing: list[str] = field(default_factory=list)
    """Declared runs of the claim's cells with no results row (a reason in brackets where the row is there)."""
    frames: list[int] = field(default_factory=list)
    seeds: int = 0
    """The fewest seeds of the rows any comparison present read (0: none present)."""
    costs: list[str] = field(default_factory=list)
    """The campaign step that trains each missing run, and its cost (emml.experiments.campaign.status)."""
    owners: dict = field(default_factory=dict)
    """Missing run name → the table whose run dir and results hold it (Table 3's DA Multi-Task: table2)."""
    apart: bool = False
    """The paper's own table fails the claim's rule (`decide_paper`): shown apart, not counted in the tallies."""
    settle: list[str] = field(default_factory=list)
    """The runs that would settle a provisional reversal, each with its campaign step and cost where known."""
    literal: list[dict] = field(default_factory=list)
    """Beside a No Aux cell trained under the warm-up: the paper-literal run's number (row, setting, metric, run,
    value)."""

    @property
    def held(self) -> str:
        """'14 of 15 hold': the comparisons present (a 'most' one counts its rows)."""
        present = [c for c in self.checks if c.outcome != MISSING]
        return f"{sum(c.outcome == HOLDS for c in present)} of {len(present)} hold" if present else ""

    @property
    def label(self) -> str:
        """The status with the seeds it rests on, always: '(on 1 seed)', '(on 3 seeds)', '(no run yet)'."""
        if not self.seeds or self.status == ONE_SEED:  # 'reversed on 1 seed' says its seeds itself
            return f"{self.status} (no comparison yet)" if self.status == UNTESTABLE else self.status
        return f"{self.status} (on {self.seeds} seed{'s' if self.seeds != 1 else ''})"


@dataclass
class Evidence:
    """The scores a claim's cells hold, and what is missing."""

    scores: dict = field(default_factory=dict)
    """(row, difficulty, aux, metric) → the scores found (every seed)."""
    evidence: list[dict] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    owners: dict = field(default_factory=dict)
    frames: set = field(default_factory=set)
    chance: Chance | None = None
    """What the scores are held against (a kind that compares tasks reads it: 'harder')."""
    curves: Curves | None = None
    """Each run's evaluation curves (ours; None for the paper's tables: their reversals are not weighed for being
    settled)."""
    seconds: dict = field(default_factory=dict)
    """Run name → the run that would give its cell its next seed ('table2/…-s1-quick')."""
    literal: list[dict] = field(default_factory=list)


def _wanted(where: dict, cell_metric: str, c) -> bool:
    return c.metric == cell_metric and all(
        getattr(c, "difficulty" if k == "difficulty" else "aux") == v for k, v in where.items()
    )


def _learning(row: dict, metric: str, difficulty: str, blind: bool, chance: Chance) -> tuple[float | None, float]:
    """A run's training score on the task of `metric` and the bar it must pass to have learned (-inf: the blind
    row, whose score is the chance line itself)."""
    train = train_of(task_of(metric)).name
    value = None if isnan(row.get(train)) else float(row[train])
    return value, (-math.inf if blind else chance.bar(train, difficulty))


def gather(claim, plan: ReportPlan, chance: Chance | None = None) -> Evidence:
    """The claim's cells read from the results of ``plan`` (the claim's table planned under a profile,
    emml/report/plan.py: results/<table>/<profile>.csv and the tables it borrows from), each run's number as the
    claim's kind reads it (`Kind.read` of a `Reading`: its results row, or its curve as every page reads it)."""
    from emml.report.cells import build_cells, paper_numbers, table_results

    kind = claim.kind_of
    table = plan.table
    results = table_results(table, plan.profile, plan.results_root)
    cells = build_cells(plan, results, paper_numbers(table.name))
    rows = {r["run_name"]: r for r in results.to_dict("records")}
    planned = plan.by_name()  # every run's config and name made once
    run_root = plan.run_root
    chance = chance if chance is not None else blind_prior(plan.profile, plan.results_root)
    columns = set(table.metrics.values())
    blind = {r.label for r in table.rows if r.model == BLIND_MODEL}
    involved = kind.involved(claim, table)
    ev = Evidence(chance=chance)
    folders, run_ids = {}, {}
    for where in kind.wheres(claim):
        for m in claim.metrics:
            cell_metric = m if m in columns else m.replace("_train", "_test")  # a train twin reads the test cell's runs
            for c in (c for c in cells if _wanted(where, cell_metric, c) and c.row in involved):
                per = len(table.cell_columns(c.row, c.metric))
                found, shown = [], {}
                for name, value in zip(c.runs, c.values):
                    row = rows[name]
                    ev.frames.add(int(row["frames"]))
                    train, bar = _learning(row, m, c.difficulty, c.row in blind, chance)
                    episodes = int(row["eval_episodes"]) * per
                    score = Score(name, int(row["seed"]), value, episodes, int(row["frames"]), train, bar, metric=m)
                    run = Reading(planned[name], row, score, columns, run_root, chance)
                    folders[name], run_ids[name] = run.folder, run.run_id
                    score = kind.read(claim, m, run)
                    if score is None:
                        ev.missing.append(kind.missing(name, m))
                        continue
                    shown[score.seed] = kind.shown(score)
                    found.append(score)
                ev.scores[(c.row, c.difficulty, c.aux, m)] = found
                second = next_seed(plan, c.row, c.difficulty, c.aux, c.metric, [s.run for s in found])
                ev.seconds.update({s.run: second for s in found})
                for run in plan.cell_runs(c.row, c.difficulty, c.aux, c.metric):
                    name = run.name
                    ev.owners[name] = run.spec.table
                    if name not in c.runs and name not in ev.missing:
                        ev.missing.append(name)
                ev.evidence.append(
                    {
                        "row": c.row,
                        "setting": _setting(c.difficulty, c.aux),
                        "metric": kind.metric_label(claim, m),
                        "values": {s.seed: s.value for s in found},
                        "shown": shown,
                        "declared": c.expected,
                        "runs": [s.run for s in found],
                        "column": m,
                    }
                )
    ev.curves = Curves(folders, run_ids)
    if kind.borrows:  # a one-seed cell borrows the spread of its row's nearest cell with two seeds or more
        ev.scores = borrow(ev.scores, spreads(claim, cells, rows, columns, involved), _setting)
        ev.literal = literal(ev.evidence, plan)
    return ev


def paper_evidence(claim, chance: Chance | None = None) -> Evidence:
    """The claim's cells read from the paper's own table (reproduce/paper/<table>.csv): each number one seed of
    PAPER_EPISODES episodes, 'learned' read on the cell itself (the paper gives no training accuracy per cell). A
    cell the paper has no number for (a training column, a curve, a diagnostic) is missing."""
    from emml.experiments.tables import load_table
    from emml.report.cells import paper_numbers

    kind = claim.kind_of
    table = load_table(claim.table)
    chance = chance if chance is not None else paper_prior()
    blind = {r.label for r in table.rows if r.model == BLIND_MODEL}
    lookup = {(r.row, r.difficulty, r.aux, r.metric): float(r.value) for r in paper_numbers(table.name).itertuples()}
    printed = {row for (row, *_) in lookup}  # our Table 4 has rows the paper's has not: they are not its claim's
    involved = kind.involved(claim, table) & printed
    ev = Evidence(chance=chance)
    for where in kind.wheres(claim):
        for m in claim.metrics:
            for d, a, metric in table.columns():
                if metric != m.replace("_train", "_test") or any(
                    (d if k == "difficulty" else a) != v for k, v in where.items()
                ):
                    continue
                for row in (r.label for r in table.rows if r.label in involved):
                    value = None if kind.curve else lookup.get((row, d, a, m))
                    bar = -math.inf if row in blind else chance.bar(train_of(task_of(m)).name, d)
                    found = [] if value is None else [Score(PAPER, 0, value, PAPER_EPISODES, 0, value, bar)]
                    ev.scores[(row, d, a, m)] = found
                    if value is None:
                        ev.missing.append(f"{row}, {_setting(d, a)}, {kind.metric_label(claim, m)} (no number)")
                    ev.evidence.append(
                        {
                            "row": row,
                            "setting": _setting(d, a),
                            "metric": kind.metric_label(claim, m),
                            "values": {0: value} if found else {},
                            "shown": {0: f"{value:.2f}"} if found else {},
                            "declared": 1,
                        }
                    )
    return ev


def judge(claim, ev: Evidence, source: str) -> Decision:
    """The claim's status from its evidence, by its kind's comparisons; ``source``: the profile's name, or PAPER."""
    from emml.experiments.tables import load_table

    kind = claim.kind_of
    table = load_table(claim.table)
    order_ = {k: i for i, k in enumerate(claim.metrics)}
    keys = sorted({(d, a, m) for (_, d, a, m) in ev.scores}, key=lambda k: (order_[k[2]], k[0], not k[1]))
    checks = kind.checks(claim, table, keys, lambda row, d, a, m: ev.scores.get((row, d, a, m), []), ev.chance)
    if ev.curves is not None:  # ours: a reversal is contradicted only when settled (the paper's numbers are printed)
        checks = settle_all(checks, ev.curves, ev.seconds)
    present = [c.seeds for c in checks if c.outcome != MISSING]
    st = status(checks, kind.single_subject)
    return Decision(
        claim.id,
        claim.text,
        claim.source,
        claim.kind,
        table.name,
        source,
        st,
        _phrase(checks),
        checks,
        ev.evidence,
        ev.missing,
        sorted(ev.frames),
        min(present) if present else 0,
        owners=ev.owners,
        literal=ev.literal,
    )


def decide(
    claim,
    profile: Profile | str,
    results_root=None,
    run_root=None,
    chance: Chance | None = None,
    plans: dict | None = None,
) -> Decision:
    """The claim decided from the results of `profile` (chance: its blind prior, `blind_prior`). ``plans``: table
    name → its report plan, filled here: claims of one table share one plan (`decide_all`)."""
    plans = plans if plans is not None else {}
    if claim.table not in plans:
        plans[claim.table] = plan_report(claim.table, profile, results_root, run_root)
    plan = plans[claim.table]
    return judge(claim, gather(claim, plan, chance), plan.profile.name)


def decide_paper(claim) -> Decision:
    """The claim decided from the paper's own table, by the same rules (chance: the paper's Text only rows); rows
    of ours the paper's table does not print (Table 4's extra instruction kinds) are not its claim's."""
    from dataclasses import replace

    from emml.report.cells import paper_numbers

    printed = set(paper_numbers(claim.table)["row"])
    if not claim.kind_of.one_row:
        claim = replace(claim, rows=tuple(r for r in claim.rows if r in printed))
    return judge(claim, paper_evidence(claim), PAPER)


def _phrase(checks: list[Check]) -> str:
    """The evidence in a phrase, per setting: how many comparisons hold, and the one that decides against."""
    groups: dict[str, list[Check]] = {}
    for c in checks:
        groups.setdefault(c.setting, []).append(c)
    parts = []
    for setting, cs in groups.items():
        present = [c for c in cs if c.outcome != MISSING]
        left = len(cs) - len(present)
        unlearned = [c for c in cs if c.chance and c.outcome != HOLDS]
        if not present:
            if unlearned and unlearned[0].high:
                values = ", ".join(dict.fromkeys(f"{c.metric} {mean(c.high):.2f}" for c in unlearned if c.high))
                parts.append(f"{setting}: {unlearned[0].subject} has not learned ({values}), {_n(left)} not run yet")
            else:
                parts.append(f"{setting}: {_n(left)} not run yet")
            continue
        text = f"{setting}: {sum(c.outcome == HOLDS for c in present)} of {len(present)} hold"
        text += f", {left} not run yet" if left else ""
        failing = [c for c in present if c.outcome != HOLDS]
        learned_lost = [c for c in failing if c.outcome == REVERSED and not c.chance]
        worst = (  # a settled reversal first (what makes the claim contradicted), then a provisional one
            next((c for c in learned_lost if not c.unsettled), None)
            or next(iter(learned_lost), None)
            or next((c for c in failing if c.chance), failing[0] if failing else None)
        )
        if worst is not None:
            note = f"; {worst.subject} has not learned" if worst.chance else ""
            compared = " ".join(x for x in (worst.metric, worst.compared) if x)
            text += f"; {worst.unsettled or worst.outcome}: {compared} ({worst.numbers}{note})"
        parts.append(text)
    return "; ".join(parts)


def _n(k: int) -> str:
    return f"{k} comparison{'s' if k != 1 else ''}"


def _setting(difficulty: str, aux: bool) -> str:
    from emml.experiments.claims.kinds import setting_text

    return setting_text(difficulty, aux)


def campaign_costs(campaign: str = "reference") -> dict[tuple[str, str], str]:
    """(table, run name) → the campaign step that trains it, its state and what it costs here and on a GPU node;
    {} when the campaign cannot be read. Keyed by table: Tables 3 and 4 both have runs named
    `dual_attention-easy-aux-sgnonly-s0-quick`. Deterministic for a given tree: it reads run dirs only."""
    try:
        from emml.experiments.campaign import load_campaign
        from emml.experiments.campaign import status as campaign_status

        rows = campaign_status(load_campaign(campaign))
    except Exception:  # noqa: BLE001 - the costs are optional: a page without them is still the page
        return {}
    out = {}
    for r in rows:
        if r.state == "done":
            continue
        here = f"~{r.seconds_left / 3600:.1f} h here" if r.seconds_left else "no estimate here"
        node = f", ~{r.node_seconds_left / 3600:.1f} h on a GPU node" if r.node_seconds_left else ""
        out[(r.table, r.run_name)] = f"campaign step `{r.step}`, {r.state}: {here}{node}"
    return out


def costs_of(d: Decision, costs: dict[tuple[str, str], str]) -> list[str]:
    """Each missing run of the decision with the step that trains it (keyed by its own table), or 'in no step of
    the campaign'."""
    out = []
    for entry in d.missing:
        name = entry.split(" ", 1)[0]
        table = d.owners.get(name, d.table)
        out.append(f"`{table}/{name}`: {costs.get((table, name), 'in no step of the campaign')}")
    return out


def decide_all(profile: Profile | str, results_root=None, costs: dict | None = None, run_root=None) -> list[Decision]:
    """Every claim of reproduce/claims.toml decided from `profile`'s results (and its runs' metrics.csv under
    `run_root`), in the file's order; with `costs` (campaign_costs), each missing run's step, and the step of each
    run that would settle a provisional reversal. A claim whose rule the paper's own table fails is marked `apart`
    (issue 81 item 4: not counted among the reproduction's verdicts). Each table is planned once for all its
    claims."""
    from emml.experiments.claims import load_claims

    profile = resolve_profile(profile)
    chance = blind_prior(profile, results_root)
    plans: dict = {}
    out = []
    for claim in load_claims().values():
        d = decide(claim, profile, results_root, run_root, chance, plans)
        if costs is not None:
            d.costs = costs_of(d, costs)
        d.settle = settle_costs(d.checks, costs or {})
        d.apart = decide_paper(claim).status not in (SUPPORTED, UNTESTABLE)  # the paper's table fails it: apart
        out.append(d)
    return out


def write_claims(
    profile: Profile | str, out=None, results_root=None, costs: dict | None = None, run_root=None, tables=None
):
    """reports/claims-<profile>.md, the page read first, and beside it its detail and figure
    (emml/report/claims_page.py; scratch/reports for a scratch profile, as the table pages: `reports_dir`).
    ``tables``: the tables whose page `make reports` writes for the profile, which the detail links (None: those
    that have a finished run of the profile)."""
    from emml.experiments.claims import load_claims
    from emml.report import eqa_test, gate_figure
    from emml.report.claims_page import page_names, write_pages
    from emml.report.tables import reports_dir

    profile = resolve_profile(profile)  # once: every claim, table and page below reads it
    folder = reports_dir(profile, out)
    folder.mkdir(parents=True, exist_ok=True)
    decisions = decide_all(profile, results_root, costs, run_root)
    claims = load_claims()
    paper = {c.id: decide_paper(c) for c in claims.values()}
    if tables is None:
        tables = _tables_with_runs({c.table for c in claims.values()}, profile, results_root)
    chance = blind_prior(profile, results_root)
    arms = eqa_test.read_arms(profile, results_root, run_root)  # each run's gate from its run dir (issue 82)
    names = page_names(profile.name)
    gate = gate_figure.figure(arms[0], [folder / names["gate_png"], folder / names["gate_pdf"]]) if arms else []
    eqa = eqa_test.finding(arms, eqa_test.paper_value(), chance, profile.name, names["gate_png"] if gate else None)
    paths = write_pages(folder, decisions, profile, paper, claims, chance, set(tables), eqa)
    return paths[0], decisions


def _tables_with_runs(names: set[str], profile: Profile, results_root) -> set[str]:
    """The tables among ``names`` that are not placeholders and have a finished run of ``profile``."""
    from emml.experiments.tables import load_table
    from emml.report.cells import table_results

    out = set()
    for name in sorted(names):
        table = load_table(name)
        if table.placeholder:
            continue
        df = table_results(table, profile, results_root)
        if df["run_name"].isin(plan_report(table, profile, results_root).names).any():  # an empty frame: none
            out.add(name)
    return out
