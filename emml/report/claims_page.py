"""The claims pages: what a reviewer reads first (reports/claims-<profile>.md: the status table, one line per claim
with its status, seeds, the paper's numbers and ours, and one figure of ours against the paper per claim), and the
detail (reports/claims-<profile>-detail.md: the rules, general then each kind's own from
emml/experiments/claims/kinds.py, then a section per claim with the numbers per row and seed, the comparisons, the
missing runs and the campaign steps that train them)."""

from __future__ import annotations

from dataclasses import dataclass

from emml.config.profiles import Profile
from emml.experiments.claims.closing import CONFIDENCE
from emml.experiments.claims.evidence import (
    CLOSING,
    LEAVE,
    ONE_SEED,
    REVERSED,
    STATUSES,
    SUPPORTED,
    UNCLEAR,
    UNKNOWN_FLAT,
    UNTESTABLE,
    Chance,
    Z,
)
from emml.experiments.claims.kinds import KINDS
from emml.report.chance import chance_text
from emml.report.claims_figure import FIGURE_WIDTH, figure

GENERAL_RULES = [
    "**supported**: every comparison of the claim holds. **contradicted**: some comparison is reversed by the same "
    "rule while the row the claim puts higher has learned its training split: it learned, and still loses. **not "
    "supported (within the error)**: the rows learned, but a gap is within the error. **not supported at this "
    "budget**: the row the claim puts higher has not learned its training split (at this budget its loss says "
    "nothing against the paper). "
    "**untestable yet**: a cell the claim compares has no finished run (the missing runs are listed, with the "
    "campaign step that trains each); numbers already there are shown.",
    "**Settled** (issue 81): a reversal counts as contradicted only when a second seed and more frames would not "
    "overturn it: (a) each row it compares has two seeds or more, or a one-seed row is still reversed once its "
    "error includes the between-seed variance of the nearest cell of the same row with two seeds (the same "
    "difficulty first, then the same aux; named in the comparison), and (b) the gap (the higher row's mean over "
    "seeds minus the lower's, per evaluation point of the runs' metrics.csv curves) is not still closing: over the "
    f"last third of the evaluations its least-squares slope against frames is not towards the claim with a "
    f"one-sided {CONFIDENCE:.0%} interval that excludes 0. Otherwise the claim is **{ONE_SEED}**, **{CLOSING}** "
    f"or, where a run's curve is not here, **{UNKNOWN_FLAT}**, and names the run that would settle it (a missing "
    "seed's run, or more frames) with its campaign step.",
    "**The paper's table first**: a claim whose rule the paper's own numbers fail is shown apart ('the paper's "
    "table does not support its text') and is not counted among the reproduction's verdicts.",
    f"**Ordering**: the higher row's mean over every seed it has minus the lower row's, against {Z:g} standard error "
    "of that gap; a row's error is the larger of its between-seed spread (sample variance / seeds, as Welch's test, "
    "with two seeds or more) and the binomial error of its rates (p(1−p)/N per seed, N the evaluation's episodes: a "
    "results row's eval_episodes, a transfer row times its instructions). One seed: binomial only, and the status "
    "says so.",
    f"**Learned**: a row has learned when the mean of its training-split scores on the task compared (sgn_train for "
    f"an SGN cell), over every seed that has one, is above chance + {LEAVE:.2f} (a run without a training score is "
    "left out, not averaged in); the blind row (Text only) is never excused. On the paper's own table, which gives "
    "no training score per cell, the cell's own number stands in for it, held against the training split's chance.",
    "**On the paper's table**: the same rules on the paper's own numbers (reproduce/paper/), each read as one seed of "
    "500 episodes (the paper gives no count; ours, the final evaluation's), against the same chance as ours; its "
    "reversals are the paper's printed numbers and are not weighed for being settled. A claim whose rule the "
    "paper's own table fails says why; a curve or a diagnostic the paper shows as a figure has no number there.",
]


def rules(chance: Chance) -> list[str]:
    """The page's rules: the general ones, each kind's own, and chance as measured for this page."""
    kinds = [kind.rule for kind in KINDS.values()]
    return [
        *GENERAL_RULES,
        *kinds,
        f"**Chance** is what a model that sees no frame scores here: {chance.source}, never below the uniform chance "
        f"(SGN 0.20, one of five objects; EQA 0.33). {chance_text(chance)}.",
    ]


def _cell(text: str) -> str:
    """Text for a Markdown table cell or line: pipes escaped, '<known_object>' kept as text (not an HTML tag)."""
    return text.replace("|", r"\|").replace("<", "&lt;")


def _paper_label(d, claim) -> str:
    if d is None:
        return "—"
    if d.status == SUPPORTED:
        return "supported"
    if d.status == UNTESTABLE:
        return "no number (a figure or a training curve)"
    return f"**fails**: {d.status}"


def thresholds(claim) -> str:
    """The numbers the project chose for a claim's rule, printed beside it."""
    parts = []
    if claim.margin is not None:
        parts.append(f"margin {claim.margin:g}")
    if claim.value is not None:
        ref = " × the reference setting's own mean" if claim.relative else ""
        parts.append(f"value {claim.value:g}{ref}")
    if claim.mark is not None:
        parts.append(f"mark '{claim.mark}'")
    return ", ".join(parts)


MAX_CELLS = 4
"""The cells of a claim the status table shows (the detail page has them all)."""


def page_names(name: str) -> dict[str, str]:
    """The files of a profile's claims pages: the page read first, its detail, its figure (PNG for the page, PDF
    for print), the EQA box's gate figure (emml/report/gate_figure.py)."""
    return {
        "page": f"claims-{name}.md",
        "detail": f"claims-{name}-detail.md",
        "png": f"claims-{name}.png",
        "pdf": f"claims-{name}.pdf",
        "gate_png": f"claims-{name}-gate.png",
        "gate_pdf": f"claims-{name}-gate.pdf",
    }


def focus_rows(claim, decision=None) -> list[str]:
    """The rows whose numbers the status table and the figure show. Given a ``decision`` that goes against the claim
    (`against`), the rows of the comparison that decides it first (issue 81 item 5: the first screen says what
    decided), then the reference row (`than`) and the claim's first row; else the reference row, then its first
    row ('best': the row it puts above every other)."""
    rows = [*([claim.than] if claim.than else []), *claim.rows[:1]]
    return list(dict.fromkeys((against(decision) if decision is not None else []) + rows))


def deciding(decision):
    """The comparison that decides against the claim while it is not supported: a settled reversal of a row that
    learned (what makes it contradicted), else a provisional one, else any reversal, else one within the error;
    None for a supported or untestable claim. A 'most' comparison stands for its first reversed row."""
    if decision.status in (SUPPORTED, UNTESTABLE):
        return None
    checks = [p for c in decision.checks for p in (c.parts if c.parts and c.outcome == REVERSED else [c])]
    ranked = (
        lambda c: c.outcome == REVERSED and not c.chance and not c.unsettled,
        lambda c: c.outcome == REVERSED and not c.chance,
        lambda c: c.outcome == REVERSED,
        lambda c: c.outcome == UNCLEAR,
    )
    return next((c for test in ranked for c in checks if test(c)), None)


def against(decision) -> list[str]:
    """The rows of the comparison that decides against the claim (`deciding`): the rows it reads (`Check.rows`:
    'Dual-Attention > Concat' reads both, 'Go to the red object ≥ 0.8' its one row); [] for a supported or untestable
    claim."""
    check = deciding(decision)
    return list(check.rows) if check is not None else []


def row_seeds(decision, rows: list[str]) -> str:
    """'Dual-Attention 3 · Text only 1': the seeds each of ``rows`` has in the claim's cells (a range, '2–3', where
    its cells differ); '—' when none has a run."""
    parts = []
    for row in rows:
        n = sorted({len(e["values"]) for e in decision.evidence if e["row"] == row and e["values"]})
        if n:
            parts.append(f"{row} {n[0]}" if len(n) == 1 else f"{row} {n[0]}–{n[-1]}")
    return " · ".join(parts) or "—"


@dataclass
class Cell:
    """One cell a claim reads, ours and the paper's."""

    label: str
    task: str
    ours: list[float]
    """Each seed's value (a success rate, a diag/* figure, or frames for a crossing)."""
    shown: str
    """Ours as the detail page writes it: the mean (a success rate, a figure) or each seed's crossing."""
    paper: float | None
    frames: bool = False
    """The numbers are frames (a 'faster' claim's crossing), not on the [0, 1] axis of the figure."""


def cells(decision, paper_decision, claim) -> list[Cell]:
    """The focus rows' cells of a decision (`focus_rows`), with the paper's number for the same cell: the cells of
    the comparison that decides against the claim first (`deciding`), then the rest in the focus rows' order. A No
    Aux cell trained under the warm-up says so, with the paper-literal run's number (no warm-up) beside it where one
    was trained (`Decision.literal`)."""
    from emml.report.claims_settle import warm_frames

    focus = focus_rows(claim, decision)
    decides = deciding(decision)

    def first(e) -> bool:
        return (
            decides is not None
            and e["row"] in decides.rows
            and (not decides.metric or e["metric"].startswith(decides.metric))
            and (not decides.setting or e["setting"].startswith(decides.setting))
        )

    entries = sorted(
        (e for e in decision.evidence if e["row"] in focus), key=lambda e: (not first(e), focus.index(e["row"]))
    )
    theirs = {
        (e["row"], e["setting"], e["metric"]): next(iter(e["values"].values()), None)
        for e in (paper_decision.evidence if paper_decision is not None else [])
    }
    literal = {(x["row"], x["setting"], x["metric"]): x for x in getattr(decision, "literal", [])}
    settings = {e["setting"] for e in entries}
    frames = claim.kind_of.reads == "crossing"
    out = []
    for e in entries:
        parts = [e["row"]] if len(focus) > 1 else []
        warm = warm_frames(e.get("runs", []))
        setting = e["setting"] + (f" (warm-up {warm / 1000:g}k)" if warm else "")
        parts += [setting] if len(settings) > 1 or warm else []
        label = ", ".join([*parts, e["metric"]])
        values = [float(v) for _, v in sorted(e["values"].items())]
        if frames:
            shown = " / ".join(e["shown"][s] for s in sorted(e["shown"])) or "—"
        else:
            shown = f"{sum(values) / len(values):.2f}" if values else "—"
        task = "diag" if claim.kind_of.reads == "figure" else ("eqa" if "EQA" in e["metric"] else "sgn")
        key = (e["row"], e["setting"], e["metric"])
        out.append(Cell(label, task, values, shown, theirs.get(key), frames))
        if key in literal:
            x = literal[key]
            twin = f"{e['setting']} (no warm-up, the paper's loss: {x['run']})"
            name = ", ".join([*([e["row"]] if len(focus) > 1 else []), twin, e["metric"]])
            out.append(Cell(name, task, [x["value"]], f"{x['value']:.2f}", theirs.get(key), frames))
    return out


def _lines(values: list[str]) -> str:
    shown = values[:MAX_CELLS]
    if len(values) > MAX_CELLS:
        shown.append(f"… {len(values) - MAX_CELLS} more")
    return "<br>".join(shown) or "—"


def counts(decisions: list) -> dict[str, int]:
    """How many of ``decisions`` have each status, every status named (0 where none has it); a claim shown apart
    (the paper's own table fails its rule, `Decision.apart`) is not counted."""
    return {s: sum(d.status == s and not getattr(d, "apart", False) for d in decisions) for s in STATUSES}


def tally(decisions: list) -> str:
    """'3 supported, 0 contradicted, …; 1 shown apart (the paper's table does not support its text)'."""
    apart = sum(getattr(d, "apart", False) for d in decisions)
    text = ", ".join(f"{v} {k}" for k, v in counts(decisions).items())
    return text + (f"; {apart} shown apart (the paper's table does not support its text)" if apart else "")


def status_text(d) -> str:
    """The status, and how many of its comparisons hold where it has several ('reversed on 1 seed (14 of 15
    hold)')."""
    present = [c for c in d.checks if c.outcome != "missing"]
    return f"{d.status} ({d.held})" if len(present) > 1 else d.status


def _row(d, claims: dict, paper: dict, names: dict) -> str:
    """One line of the status table."""
    claim = claims[d.id]
    cs = cells(d, paper.get(d.id), claim)
    shown = focus_rows(claim, d)
    return (
        f"| [{d.id}]({names['detail']}#{d.id}) | {status_text(d)} | {_cell(row_seeds(d, shown))} | "
        + " | ".join(
            _lines(col)
            for col in (
                [_cell(c.label) for c in cs],
                ["—" if c.paper is None else f"{c.paper:.2f}" for c in cs],
                [_cell(c.shown) for c in cs],
            )
        )
        + f" | {_paper_label(paper.get(d.id), claim)} |"
    )


def quick_page(decisions: list, profile: Profile, paper: dict, claims: dict, findings: list[str] = ()) -> str:
    """The page a reviewer reads first: a line of counts, the status table (each claim's status, seeds, the paper's
    numbers and ours on its focus rows, its status on the paper's own table), the figure, ``findings`` (markdown
    lines: a finding beyond the claims, e.g. emml/report/eqa_test.py's), and the way to the detail."""
    names = page_names(profile.name)
    frames = sorted({f for d in decisions for f in d.frames})
    inferred = sum(claims[d.id].inferred for d in decisions)
    lines = [
        f"# Claims ({profile.name})",
        "",
        f"{len(decisions)} claims of the paper ({len(decisions) - inferred} it states, {inferred} inferred from its "
        f"tables; reproduce/claims.toml) decided from the '{profile.name}' profile's results "
        f"({', '.join(f'{f:,}' for f in frames) or 'no'} frames per run) and from the paper's own tables, by the same "
        "rules. Here: " + tally(decisions) + ". Regenerated by `make reports`.",
        "",
        "| Claim | Status | Seeds | Cells (focus rows) | Paper | Ours | On the paper's table |",
        "|:--|:--|--:|:--|--:|--:|:--|",
    ]
    apart = [d for d in decisions if getattr(d, "apart", False)]
    lines += [_row(d, claims, paper, names) for d in decisions if d not in apart]
    if apart:
        lines += [
            "",
            "**The paper's table does not support its text** (its own numbers fail the claim's rule; not counted "
            "above): ours shown for the record.",
            "",
            *lines[4:6],
            *(_row(d, claims, paper, names) for d in apart),
            "",
            *(f"- {d.id}: {_cell(claims[d.id].on_paper)}." for d in apart if claims[d.id].on_paper),
        ]
    settle = [(d.id, x) for d in decisions if d not in apart for x in getattr(d, "settle", [])]
    if settle:
        lines += ["", "What would settle the provisional verdicts (the runs each names, and their campaign step):", ""]
        lines += [f"- {i}: {_cell(x)}" for i, x in settle]
    lines += [
        "",
        f"![Ours against the paper, per claim]({names['png']})",
        "",
        f"Ours (the mean over seeds, each seed a hollow point) against the paper (×) on each claim's focus rows, "
        f"SGN in blue, EQA in orange, a `diag/*` figure in green ([PDF]({names['pdf']}), {FIGURE_WIDTH:g} in wide). "
        "The focus rows are the row a claim compares with and its first row (for 'best', the row it puts above "
        "every other), and for a claim not supported the rows of the comparison that goes against it; a 'faster' "
        "claim's crossings are frames, in the table only. Seeds: per focus row, the seeds of its cells. A No Aux "
        "cell says when its runs trained under the warm-up (runs …-noaux-warm400000-…: the answer kept off the "
        "image for the first 400k frames, issue 61), with the paper-literal run (no warm-up) beside it where one "
        "was trained.",
        "",
        *findings,
        f"Every claim's comparisons, the numbers per row and seed, the decision rules, the runs still missing and the "
        f"campaign step that trains each: [{names['detail']}]({names['detail']}).",
    ]
    if profile.name != "paper":
        lines += [
            "",
            f"The '{profile.name}' profile is not the paper's protocol (fewer frames, smaller input: each table page "
            "lists its deviations): 'not supported at this budget' says no more than that.",
        ]
    return "\n".join(lines) + "\n"


def detail_page(decisions: list, profile: Profile, paper: dict, claims: dict, chance: Chance, tables=None) -> str:
    """The detail: one line per claim, the rules, then a section per claim. ``tables``: the tables whose page
    (<table>-<profile>.md) lies beside this one; a claim of another table names its table without a link (None:
    every claim's table is linked)."""
    names = page_names(profile.name)
    lines = [
        f"# Claims ({profile.name}): the detail",
        "",
        f"Each claim of [{names['page']}]({names['page']}) with the numbers per row and seed that decide it, by the "
        "rules below. Here: " + tally(decisions) + ". Regenerated by `make reports`.",
        "",
        "| Claim | Status | On the paper's table | Evidence |",
        "|:--|:--|:--|:--|",
    ]
    for d in decisions:
        label = d.label + (" (shown apart: not counted)" if getattr(d, "apart", False) else "")
        lines.append(
            f"| [{d.id}](#{d.id}) | {label} | {_paper_label(paper.get(d.id), claims[d.id])} | {_cell(d.phrase)} |"
        )
    lines += ["", "## Decision rules", ""] + [f"- {r}" for r in rules(chance)]
    if profile.name != "paper":
        lines += [
            f"- The '{profile.name}' profile is not the paper's protocol (fewer frames, smaller input: each table page "
            "lists its deviations): 'not supported at this budget' says no more than that.",
        ]
    for d in decisions:
        claim = claims[d.id]
        lines += ["", f'<a id="{d.id}"></a>', "", f"## {d.id}: {d.label}", "", f"> {d.text}", ""]
        if claim.inferred:
            lines += [f"Not a sentence of the paper: inferred from its {d.table.replace('table', 'Table ')}.", ""]
        chosen = thresholds(claim)
        page = f"{d.table}-{profile.name}.md"
        where = (
            f"[{page}]({page})"
            if tables is None or d.table in tables
            else f"{d.table.replace('table', 'Table ')} (no page at this profile: none of its runs has finished)"
        )
        lines += [
            f"Paper: {d.source}. Kind `{d.kind}`"
            + (f" ({chosen}: ours, not the paper's)" if chosen and claim.kind_of.reads != "crossing" else "")
            + f", decided on {where}.",
            "",
        ]
        seeds = sorted({s for e in d.evidence for s in e["values"]})
        if seeds:
            lines += ["| Row | Setting | Metric | " + " | ".join(f"seed {s}" for s in seeds) + " |"]
            lines += ["|:--|:--|:--|" + "--:|" * len(seeds)]
            for e in d.evidence:
                vals = " | ".join(e["shown"].get(s, "—") for s in seeds)
                lines.append(f"| {_cell(e['row'])} | {e['setting']} | {e['metric']} | {vals} |")
            lines.append("")
        elif d.evidence:
            lines += [f"No run of its cells has finished ({len(d.evidence)} cells).", ""]
        lines += ["Comparisons:", ""] + [
            f"- {_cell(c.what)}: **{c.outcome}** ({_cell(c.detail)}){_settled(c)}" for c in d.checks
        ]
        if getattr(d, "settle", None):
            lines += ["", "What would settle it:", ""] + [f"- {_cell(x)}" for x in d.settle]
        p = paper.get(d.id)
        if p is not None:
            lines += ["", f"On the paper's own table: **{_paper_label(p, claim)}** ({_cell(p.phrase)})."]
            if claim.on_paper:
                lines += ["", f"Why the paper's own numbers fail the rule: {claim.on_paper}"]
        if d.missing:
            lines += ["", f"Missing runs ({len(d.missing)}): " + ", ".join(f"`{m}`" for m in d.missing) + "."]
        if d.costs:
            lines += ["", "The campaign steps that train them (emml campaign status reference):", ""]
            lines += [f"- {c}" for c in d.costs]
    return "\n".join(lines) + "\n"


def _settled(check) -> str:
    """A reversal's weighing for being settled, for the detail's comparison line ('' when it was not weighed)."""
    if not check.settlement:
        return ""
    return f"; **{check.unsettled or 'settled'}**: {_cell(check.settlement)}"


def write_pages(
    folder, decisions: list, profile: Profile, paper: dict, claims: dict, chance: Chance, tables=None, findings=()
):
    """The claims page (with ``findings``, `quick_page`), its detail and its figure into ``folder``; returns their
    paths, the page first."""
    from pathlib import Path

    from emml.runs.atomic import write_text
    from emml.runs.diskspace import RERUN

    folder = Path(folder)
    names = page_names(profile.name)
    page, detail = folder / names["page"], folder / names["detail"]
    write_text(page, quick_page(decisions, profile, paper, claims, findings), then=RERUN)  # whole or not at all
    write_text(detail, detail_page(decisions, profile, paper, claims, chance, tables), then=RERUN)
    figs = [folder / names["png"], folder / names["pdf"]]
    shown = {d.id: cells(d, paper.get(d.id), claims[d.id]) for d in decisions}
    figure(decisions, shown, {d.id for d in decisions if claims[d.id].kind_of.curve}, figs)
    return [page, detail, *figs]
