"""The deviations from the paper in force for the runs a report shows, read from the runs' own configs (their
results.json, emml/report/saved_config.py) against the declared list of emml/experiments/fidelity.py, and grouped: a
line said once with the runs it holds for ("all 4 runs", "the Easy runs (3)"), never written by hand."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from emml.config.env_kinds import env_label
from emml.experiments import fidelity

SAVED, NO_CONFIG, REFERENCE, DECLARED = "saved", "no saved config", "reference", "declared"
"""Where a run's config came from: its results.json; the registry because its results.json has no config yet
(`emml backfill-config`); the registry because the run dir is not here (a reference row of the results CSV); the
registry for a run not finished yet (a table with no finished runs shows the deviations it is declared with)."""


@dataclass
class ShownRun:
    """A run a report shows, with the config its deviations are read from."""

    name: str
    """Run name (`TrainConfig.run_name`)."""
    attrs: dict
    """What a group of runs can be named by: row, difficulty, aux (the RunSpec's)."""
    config: dict
    """The resolved config (`emml.experiments.fidelity.resolve`)."""
    source: str
    """SAVED, NO_CONFIG, REFERENCE or DECLARED."""
    skip: frozenset = field(default_factory=frozenset)
    """Fields the run's table row sets on purpose (its overrides, e.g. 'env.shaping' for 'w/o Reward Shaping'): the
    experiment, not a deviation. Only a paper table's rows (reproduce/table*.toml) skip theirs: an experiment's rows
    (reproduce/experiments/) set what the paper does not, and their reports name it."""


def shown_run(run, run_root: str | Path | None = None, row: dict | None = None, declared: bool = False) -> ShownRun:
    """A planned run (`emml.experiments.plan.PlannedRun`, its config, name and folder made once) with the config its
    deviations are read from: its run dir's results.json when there, else the config its RunSpec gives under the
    plan's profile (saying why). ``row``: its results CSV row, whose `eval_episodes` is the size of the evaluation its
    score came from (a re-scored run's differs from its config's). ``run_root``, when given, is the root the caller
    planned under: it must be the run's own (a ValueError names both), since the run dir read is the run's."""
    from emml.config.paths import project_path
    from emml.runs.records import note
    from emml.runs.rundir import RunDirError, saved_config

    spec, name, run_dir = run.spec, run.name, run.directory
    if run_root is not None and project_path(run_root) != project_path(run.cfg.run_root):
        raise ValueError(f"run_root={run_root}: {name} was planned under run_root={run.cfg.run_root}")
    try:
        saved = saved_config(run_dir)
    except RunDirError as e:  # one damaged run dir does not stop a report: named, then shown as declared
        note(f"{e}; {name} is shown with the config its table declares")
        saved = None
    if saved is not None:
        source = SAVED
    else:
        source = DECLARED if declared else NO_CONFIG if run_dir.exists() else REFERENCE
        saved = run.cfg.to_dict()
    from emml.experiments.table_files import list_tables

    # a paper table's row sets its overrides on purpose (Table 3's ablations); an experiment's rows are not the paper's;
    # a row's departures (its No Aux overrides, issue 48) are deviations all the same
    paper_row = spec.table in list_tables()
    own = [k for k in spec.overrides if k not in spec.departures]
    skip = frozenset(k.replace("model_options.", "model.") for k in own) if paper_row else frozenset()
    attrs = {"row": spec.row, "difficulty": spec.difficulty, "aux": spec.aux}
    config = fidelity.resolve(saved)
    if row is not None and row.get("eval_episodes") is not None:
        config["score_episodes"] = int(row["eval_episodes"])
    return ShownRun(name, attrs, config, source, skip)


_ATTR_TEXT = {
    "difficulty": env_label,
    "aux": lambda v: "Aux" if v else "No-Aux",
    "row": str,
}


def _by_attribute(group: set[str], runs: list[ShownRun]) -> str | None:
    """'the Easy runs', 'the GA and FiLM runs': ``group`` named by the values of one attribute, when it is exactly the
    runs having them; None when no attribute does."""
    for attr in ("difficulty", "aux", "row"):
        values = {r.attrs[attr] for r in runs if r.name in group}
        if {r.name for r in runs if r.attrs[attr] in values} == group:
            return "the " + " and ".join(_ATTR_TEXT[attr](v) for v in sorted(values, key=str)) + " runs"
    return None


def who(group: list[ShownRun], runs: list[ShownRun]) -> str:
    """The runs of ``group`` named as briefly as ``runs`` allow: 'all 4 runs', 'the Easy runs (28 of 56)', 'all but
    the w/o SA runs (42 of 48)', else their names."""
    names = {r.name for r in group}
    if len(names) == len(runs):
        return {1: "the run", 2: "both runs"}.get(len(runs), f"all {len(runs)} runs")
    count = f"({len(names)} of {len(runs)})"
    texts = []
    if (text := _by_attribute(names, runs)) is not None:
        texts.append(f"{text} {count}")
    if (text := _by_attribute({r.name for r in runs} - names, runs)) is not None:
        texts.append(f"all but {text} {count}")
    if texts:
        return min(texts, key=len)
    listed = sorted(names)
    more = f" and {len(listed) - 4} more" if len(listed) > 4 else ""
    return f"{len(listed)} of {len(runs)} runs: {', '.join(listed[:4])}{more}"


def grouped(runs: list[ShownRun], lines_of) -> list[tuple[str, str]]:
    """(line, who) for every distinct line ``lines_of(run)`` gives, in the order they first appear."""
    holders: dict[str, list[ShownRun]] = {}
    for run in runs:
        for line in lines_of(run):
            holders.setdefault(line, []).append(run)
    return [(line, who(group, runs)) for line, group in holders.items()]


@dataclass
class Deviations:
    """What a report says about the runs it shows."""

    deviations: list[tuple[str, str]]
    """(line, which runs): where the runs differ from what the paper states."""
    choices: list[tuple[str, str]]
    """(line, which runs): our choices in force where the paper is silent."""
    sources: str
    """Where the configs came from, in words."""


def noaux_schedule(plan) -> list[tuple[str, str]]:
    """The No Aux warm-up as ``table`` declares it (`ModelConfig.answer_gate_frames`, issue 61: one rule for every No
    Aux row whose answer reads the image), said once per table: (line, the rows it applies to) per schedule its No Aux
    rows declare (one, where the tables keep the rule: tests/experiments/test_tables.py); [] when no No Aux row has
    one. The line is the deviation each run's config gives (`fidelity.WARMUP`), so that `summarise` says it here
    instead of once per group of runs. ``plan``: the table's report plan (emml/report/plan.py), its first seed's
    runs read."""
    from emml.experiments.fidelity import answer_reads_image

    rows: dict[int, list[str]] = {}
    blind: list[str] = []
    first = plan.profile.seeds[0]
    for run in plan.runs:
        spec = run.spec
        if spec.aux or spec.seed != first:
            continue
        frames = run.cfg.model_options.get("answer_gate_frames", 0)
        if not frames and not answer_reads_image(spec.model):
            blind.append(spec.row)
        rows.setdefault(frames, [])
        if spec.row not in rows[frames]:
            rows[frames].append(spec.row)
    if not any(rows):
        return []
    (warmup,) = [p for p in fidelity.PAPER if p.label == fidelity.WARMUP]
    out = []
    for frames, labels in rows.items():
        if not frames:
            continue
        others = [r for f, rs in rows.items() if f != frames for r in rs]
        if not others:
            who = "the No Aux runs of every row: "
        elif set(others) <= set(blind):
            who = f"the No Aux runs of every row but {' and '.join(others)} (its answer reads no image): "
        else:
            who = "the No Aux runs of the rows "
        out.append((warmup.deviation({"model.answer_gate_frames": frames}), who + ", ".join(labels)))
    return out


def summarise(runs: list[ShownRun], schedule: list[tuple[str, str]] | None = None) -> Deviations:
    """Deviations and choices of ``runs``, grouped, with where their configs came from. ``schedule``: the table's
    No Aux warm-up (`noaux_schedule`), said once with the rows it applies to, in place of the runs' own lines that
    say the same (a run under another schedule keeps its line)."""
    devs = grouped(runs, lambda r: fidelity.deviations(r.config, r.skip))
    if schedule:
        said = {line for line, _ in schedule}
        at = next((i for i, (line, _) in enumerate(devs) if line in said), len(devs))
        kept = [d for d in devs if d[0] not in said]
        devs = kept[:at] + list(schedule) + kept[at:]
    choices = grouped(runs, lambda r: fidelity.choices(r.config))
    counts = {s: sum(r.source == s for r in runs) for s in (SAVED, NO_CONFIG, REFERENCE, DECLARED)}
    words = {
        SAVED: "their saved config (runs/<table>/<run>/results.json)",
        NO_CONFIG: "the registry's config (their results.json has no config yet: `emml backfill-config`)",
        REFERENCE: "the registry's config (no run dir here: reference rows of the results CSV)",
        DECLARED: "the registry's config as declared (no run finished yet)",
    }
    parts = [f"{n} run{'s' if n > 1 else ''} from {words[s]}" for s, n in counts.items() if n]
    return Deviations(devs, choices, "; ".join(parts))


def markdown(d: Deviations) -> str:
    """The deviations as Markdown lists (under a table's caption)."""
    paper = "each run's config against the paper's values, `emml/experiments/fidelity.py`"
    out = [f"**Deviations from the paper** ({paper}):", ""]
    out += [f"- {line}: {holders}" for line, holders in d.deviations] or ["- none"]
    out += ["", "**Where the paper is silent**, our choices in force:", ""]
    out += [f"- {line}: {holders}" for line, holders in d.choices] or ["- none"]
    out += ["", f"Configs: {d.sources}."]
    return "\n".join(out)


def sentence(d: Deviations) -> str:
    """The deviations in one paragraph (a LaTeX caption, a figure's caption beside it)."""
    devs = "; ".join(f"{line} [{holders}]" for line, holders in d.deviations) or "none"
    ours = "; ".join(f"{line} [{holders}]" for line, holders in d.choices) or "none"
    return f"Deviations from the paper: {devs}. Where the paper is silent, ours: {ours}. Configs: {d.sources}."
