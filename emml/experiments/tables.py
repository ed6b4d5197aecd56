"""The experiment registry: reproduce/tableN.toml → `Table` → `RunSpec`s (one per setting and seed).

A table file reads like the paper's table (Chaplot et al. 2019, arXiv:1902.01385): `[[rows]]` are its rows (a
model, optionally with config overrides), `[columns]` its columns (difficulties × aux × metrics). Each
(row, difficulty, aux) is a *setting*; a setting is trained once per seed of the profile (reproduce/profiles.toml).
A row with `metric_overrides` trains one setting per metric (Table 3's "DA Single-Task": SGN cells from SGN-only
runs, EQA cells from EQA-only runs). Run names derive from the config (`emml.runs.naming.run_name`), and two runs of a
table may not share one. A malformed file fails with the file, the key and what is wrong.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import tomllib

from emml.config.env_kinds import ENV_KINDS
from emml.config.profiles import Profile, resolve_profile
from emml.config.schema import TrainConfig, apply_overrides
from emml.experiments.metrics import BY_NAME, METRICS, TRANSFER_METRICS
from emml.experiments.table_files import find_table, list_tables, table_path
from emml.runs.naming import run_name

STATUSES = ("active", "placeholder")
DIFFICULTIES = tuple(ENV_KINDS)
"""Columns of a table: the Doom difficulties, and the House domain (Table 5, Appendix C): emml/config/env_kinds.py."""
TOP_KEYS = ("title", "paper_label", "status", "row_header", "columns", "rows", "transfer")
COLUMN_KEYS = ("difficulties", "aux", "metrics")
ROW_KEYS = ("label", "model", "overrides", "metric_overrides", "noaux_overrides", "from_table", "more_seeds")
MORE_SEEDS_KEYS = ("profile", "difficulty", "aux", "seeds")
TRANSFER_KEYS = ("model", "overrides", "words", "detector")
TRANSFER_RUN_ROW = "Training run (before transfer)"
"""The `RunSpec.row` of a transfer table's runs: one training setting serves every row (its curve's label)."""
TRANSFER_ROW_KEYS = ("label", "instructions", "extra")


@dataclass(frozen=True)
class Transfer:
    """A transfer table's one training setting (per difficulty, aux and seed) and what is appended after it
    (§5.4): every row reads its instructions' scores from those runs (emml/eval/transfer.py)."""

    model: str
    """Model registry name of the trained policy (Dual-Attention)."""
    overrides: dict
    """TrainConfig overrides of the training runs (SGN only, the training instructions' vocabulary)."""
    words: tuple[str, ...]
    """The new words, in the order their detector channels are appended."""
    detector: str
    """Detector kind (emml.eval.transfer.DETECTORS)."""


@dataclass(frozen=True)
class RunSpec:
    """One training run of a table: a setting (row, difficulty, aux, overrides) and a seed."""

    table: str
    """Table name (tableN), also the MLflow experiment and the results/<table>/ folder."""
    row: str
    """The paper's row label the run fills (e.g. 'Dual-Attention', 'w/o SA')."""
    model: str
    """Model registry name (`emml models`)."""
    difficulty: str
    """'easy' or 'hard'."""
    aux: bool
    """Trained with the auxiliary task."""
    seed: int
    """Seed (from the profile's `seeds`)."""
    overrides: dict = field(default_factory=dict)
    """TrainConfig fields by dotted name (e.g. {'env.shaping': False}) applied after the profile."""
    metrics: tuple[str, ...] = ()
    """The results columns this run fills in its row."""
    transfer: Transfer | None = None
    """Transfer tables: what to append and score after training (emml/eval/transfer.py); None otherwise."""
    instructions: tuple[str, ...] = ()
    """Transfer tables: the instructions scored after training (every row's)."""
    departures: tuple[str, ...] = ()
    """The keys of `overrides` that depart from the paper rather than define the row (a row's `noaux_overrides`):
    the reports list them as deviations, where the row's own overrides are the experiment."""

    def to_config(self, profile: Profile | str, **fields) -> TrainConfig:
        """The run's TrainConfig under `profile` (a name is looked up; extra `fields`, e.g. run_root, go to
        TrainConfig)."""
        return resolve_profile(profile).config(
            self.difficulty,
            self.overrides,
            model=self.model,
            aux=self.aux,
            seed=self.seed,
            table=self.table,
            **fields,
        )

    def run_name(self, profile: Profile | str) -> str:
        profile = resolve_profile(profile)
        return run_name(self.to_config(profile), profile)


@dataclass(frozen=True)
class MoreSeeds:
    """Seeds one setting of a row trains beyond its profile's (`more_seeds` in a table file): the stated model's
    spread (issue 82: Table 2's Dual-Attention, Easy · Aux, on five seeds at the quick profile)."""

    profile: str
    """The profile they apply under (reproduce/profiles.toml); no other profile plans them."""
    difficulty: str
    """The setting's difficulty column."""
    aux: bool
    """The setting's aux column."""
    seeds: tuple[int, ...]
    """The seeds added after the profile's own."""


@dataclass(frozen=True)
class Row:
    """A row of the paper's table."""

    label: str
    """The paper's label, used to join with reproduce/paper/<table>.csv."""
    model: str
    """Model registry name."""
    overrides: dict = field(default_factory=dict)
    """Config overrides for every run of the row."""
    metric_overrides: dict = field(default_factory=dict)
    """metric → extra overrides: the row's cells of that metric come from runs with them."""
    instructions: tuple[str, ...] = ()
    """Transfer tables: the test instructions the row's cells average over."""
    extra: bool = False
    """Transfer tables: a row of ours below the paper's (test instructions its table does not list)."""
    from_table: str | None = None
    """The row's runs are that table's (same run names, run dirs and results rows), not trained again: Table 3's
    "DA Multi-Task" is Table 2's Dual-Attention."""
    noaux_overrides: dict = field(default_factory=dict)
    """Extra overrides for the row's runs without the auxiliary task only (over `overrides` and `metric_overrides`):
    Dual-Attention's No Aux runs keep the answer loss to the GA2 gate (issue 48, docs/fidelity.md 'No Aux')."""
    more_seeds: tuple[MoreSeeds, ...] = ()
    """Settings of the row that train more seeds than the profile's, under one named profile (`MoreSeeds`)."""

    def seeds(self, seeds: list[int], profile: str | None, difficulty: str, aux: bool) -> list[int]:
        """The seeds of one setting: the profile's, then its `more_seeds` under that profile."""
        more = [
            s
            for m in self.more_seeds
            if (m.profile, m.difficulty, m.aux) == (profile, difficulty, aux)
            for s in m.seeds
        ]
        return list(seeds) + [s for s in more if s not in seeds]

    def settings(self, metrics: tuple[str, ...]) -> list[tuple[dict, tuple[str, ...]]]:
        """(overrides, metrics filled) for each distinct setting of the row."""
        if not self.metric_overrides:
            return [(dict(self.overrides), metrics)]
        return [({**self.overrides, **self.metric_overrides[m]}, (m,)) for m in metrics]

    def for_aux(self, overrides: dict, aux: bool) -> tuple[dict, tuple[str, ...]]:
        """A setting's overrides for its runs with (``aux``) or without the auxiliary task, and which of them depart
        from the paper (`RunSpec.departures`: the No Aux overrides)."""
        extra = {} if aux else self.noaux_overrides
        return {**overrides, **extra}, tuple(extra)


@dataclass(frozen=True)
class Table:
    """A paper table as data: rows, columns and where its numbers come from."""

    name: str
    """File stem: table2, table3, …"""
    path: Path
    """The TOML file."""
    title: str
    """The paper's caption (shortened where long)."""
    paper_label: str
    """The LaTeX label of the paper's table."""
    status: str
    """'active' (declares runs) or 'placeholder' (completed by its own issue; no runs)."""
    row_header: str = "Model"
    """Header of the row-label column."""
    rows: tuple[Row, ...] = ()
    difficulties: tuple[str, ...] = ()
    aux: tuple[bool, ...] = ()
    metrics: dict = field(default_factory=dict)
    """Column label (SGN) → results column (sgn_test), in the paper's order."""
    transfer: Transfer | None = None
    """A transfer table (Table 4): rows are instruction types read from one training setting."""

    @property
    def placeholder(self) -> bool:
        return self.status == "placeholder"

    def columns(self) -> list[tuple[str, bool, str]]:
        """(difficulty, aux, metric) for every cell column, in the paper's order."""
        return [(d, a, m) for d in self.difficulties for a in self.aux for m in self.metrics.values()]

    def runs(self, seeds: list[int], profile: str | None = None) -> list[RunSpec]:
        """Every run: rows × difficulties × aux × row settings × seeds (a transfer table: difficulties × aux ×
        seeds, every row read from them); ``profile``: the profile's name, whose rows' `more_seeds` are added (None:
        the seeds given only)."""
        out = []
        if self.transfer is not None:
            t = self.transfer
            texts = tuple(x for row in self.rows for x in row.instructions)
            metrics = tuple(self.metrics.values())
            for difficulty in self.difficulties:
                for aux in self.aux:
                    for seed in seeds:
                        out.append(
                            RunSpec(
                                self.name,
                                TRANSFER_RUN_ROW,
                                t.model,
                                difficulty,
                                aux,
                                seed,
                                t.overrides,
                                metrics,
                                t,
                                texts,
                            )
                        )
            return out
        for row in self.rows:
            for difficulty in self.difficulties:
                for aux in self.aux:
                    for overrides, metrics in row.settings(tuple(self.metrics.values())):
                        settings, departures = row.for_aux(overrides, aux)
                        owner = row.from_table or self.name
                        for seed in row.seeds(seeds, profile, difficulty, aux):
                            out.append(
                                RunSpec(
                                    owner,
                                    row.label,
                                    row.model,
                                    difficulty,
                                    aux,
                                    seed,
                                    dict(settings),
                                    metrics,
                                    departures=departures,
                                )
                            )
        return out

    def cell_runs(self, row: str, difficulty: str, aux: bool, metric: str, runs: list[RunSpec]) -> list[RunSpec]:
        """The runs (one per seed) whose `metric` fills the cell."""
        return [
            r
            for r in runs
            if (r.row == row or self.transfer is not None)
            and r.difficulty == difficulty
            and r.aux == aux
            and metric in r.metrics
        ]

    def curve_rows(self) -> list[str]:
        """The `RunSpec.row` values to draw one training curve each for: the rows, or a transfer table's one
        training setting."""
        return [TRANSFER_RUN_ROW] if self.transfer is not None else [r.label for r in self.rows]

    def cell_columns(self, row: str, metric: str) -> list[str]:
        """The results columns whose mean is a run's value for the cell: [metric], or for a transfer table one
        `<metric>:<instruction>` column per instruction of the row (`Metric.column`: Table 4's sgn_transfer, as
        emml/eval/transfer.py writes it)."""
        if self.transfer is None:
            return [metric]
        declared = BY_NAME[metric]
        return [declared.column(x) for r in self.rows if r.label == row for x in r.instructions]


def load_table(name: str, path: Path | None = None) -> Table:
    """Load and validate reproduce/<name>.toml (or `path`); `name` may also be the path of a .toml file of one's
    own (its name is then the file's stem, `own_table`), or ``experiments/<x>`` (reproduce/experiments/<x>.toml,
    named ``<x>`` as a file of one's own is): emml/experiments/table_files.py finds the file."""
    if path is None:
        name, path = find_table(name)
    path = Path(path)
    key = (name, path, path.read_bytes(), *(table_path(t).read_bytes() for t in list_tables()))
    if key not in LOADED:
        try:
            data = tomllib.loads(key[2].decode())
        except tomllib.TOMLDecodeError as e:
            raise ValueError(f"{path}: not valid TOML: {e}") from e
        LOADED[key] = _parse(name, path, data)
    return LOADED[key]


LOADED: dict[tuple, Table] = {}
"""The tables validated in this process, by name, file and the bytes of that file and of the tables of reproduce/ it
may borrow runs from (`_from_table`): an edit to either is read again. Validation names every run of the table
(`_check_runs`), and the claims read each table once per claim: writing the claims page twice (a test, profiled beside
a training on 2 cores) spent 31 of its 64 s in 333 loads of four tables; 43 s in all with this."""


def _err(path: Path, key: str, what: str) -> ValueError:
    return ValueError(f"{path}: key {key!r}: {what}")


def _check_keys(path: Path, where: str, data: dict, allowed: tuple[str, ...]) -> None:
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise _err(path, f"{where}{unknown[0]}", f"unknown key; allowed keys: {', '.join(allowed)}")


def _section(path: Path, name: str, raw, keys: tuple[str, ...], required: tuple[str, ...] | None = None) -> dict:
    """A TOML table with no key but ``keys``, holding every ``required`` one (default: all of ``keys``)."""
    raw = _typed(path, name, raw, dict, "a table")
    _check_keys(path, f"{name}.", raw, keys)
    for key in keys if required is None else required:
        if key not in raw:
            raise _err(path, f"{name}.{key}", "missing")
    return raw


def _model_name(path: Path, key: str, value) -> str:
    """A model registry name (`emml models`)."""
    from emml.models import MODELS, PLUGIN_HINT

    if value not in MODELS:
        raise _err(path, key, f"unknown model {value!r}; known models: {', '.join(MODELS)}; {PLUGIN_HINT}")
    return value


def _config(path: Path, key: str, model: str, overrides: dict) -> TrainConfig:
    """The validated TrainConfig that ``overrides`` give ``model``; a bad override fails naming ``key``."""
    from emml.models import model_config  # the model registry's check of the options (it imports torch)

    try:
        cfg = apply_overrides(TrainConfig(model=model), overrides, source="override").validate()
        model_config(cfg.model, **cfg.model_options)
        return cfg
    except ValueError as e:
        raise _err(path, key, str(e)) from e


def _typed(path: Path, key: str, value, kind: type, what: str):
    if not isinstance(value, kind):
        raise _err(path, key, f"must be {what}, got {value!r}")
    return value


def _parse(name: str, path: Path, data: dict) -> Table:
    _check_keys(path, "", data, TOP_KEYS)
    for key in ("title", "paper_label", "status"):
        if key not in data:
            raise _err(path, key, "missing")
        _typed(path, key, data[key], str, "a string")
    if data["status"] not in STATUSES:
        raise _err(path, "status", f"{data['status']!r} is not allowed; choose one of {', '.join(STATUSES)}")
    common = dict(
        name=name,
        path=path,
        title=data["title"],
        paper_label=data["paper_label"],
        status=data["status"],
        row_header=_typed(path, "row_header", data.get("row_header", "Model"), str, "a string"),
    )
    if data["status"] == "placeholder":
        for key in ("rows", "columns"):
            if key in data:
                raise _err(path, key, "a placeholder table declares no runs; set status = 'active' to add them")
        return Table(**common)
    if "transfer" in data:
        columns = _parse_columns(path, data, TRANSFER_METRICS)
        transfer, dataset = _parse_transfer(path, data)
        rows = _parse_transfer_rows(path, data, transfer, dataset)
        table = Table(**common, rows=rows, transfer=transfer, **columns)
    else:
        columns = _parse_columns(path, data)
        rows = _parse_rows(path, data, tuple(columns["metrics"].values()), no_aux=False in columns["aux"])
        table = Table(**common, rows=rows, **columns)
    _check_runs(path, table)
    return table


def _parse_columns(path: Path, data: dict, allowed: tuple[str, ...] = METRICS) -> dict:
    if "columns" not in data:
        raise _err(path, "columns", "missing: an active table needs [columns] difficulties, aux, metrics")
    cols = _section(path, "columns", data["columns"], COLUMN_KEYS)
    difficulties = _typed(path, "columns.difficulties", cols["difficulties"], list, "a list")
    for d in difficulties:
        if d not in DIFFICULTIES:
            raise _err(path, "columns.difficulties", f"{d!r} is not allowed; choose from {', '.join(DIFFICULTIES)}")
    aux = _typed(path, "columns.aux", cols["aux"], list, "a list of booleans")
    if not aux or not all(isinstance(a, bool) for a in aux):
        raise _err(path, "columns.aux", f"must be a non-empty list of booleans, got {aux!r}")
    metrics = _typed(path, "columns.metrics", cols["metrics"], dict, "a table of label = results column")
    for label, key in metrics.items():
        if key not in allowed:
            raise _err(path, f"columns.metrics.{label}", f"{key!r} is not allowed; choose one of {', '.join(allowed)}")
    if not difficulties or not metrics:
        raise _err(path, "columns", "difficulties and metrics must not be empty")
    return {"difficulties": tuple(difficulties), "aux": tuple(aux), "metrics": dict(metrics)}


def _parse_rows(path: Path, data: dict, metrics: tuple[str, ...], no_aux: bool = True) -> tuple[Row, ...]:
    """The rows; ``no_aux``: the table has runs without the auxiliary task (else `noaux_overrides` play no part)."""
    raw = _typed(path, "rows", data.get("rows", []), list, "an array of tables ([[rows]])")
    if not raw:
        raise _err(path, "rows", "an active table needs at least one [[rows]]")
    rows, labels = [], set()
    for i, r in enumerate(raw):
        where = f"rows[{i}]"
        r = _section(path, where, r, ROW_KEYS, required=("label", "model"))
        for key in ("label", "model"):
            _typed(path, f"{where}.{key}", r[key], str, "a string")
        if r["label"] in labels:
            raise _err(path, f"{where}.label", f"{r['label']!r} appears twice")
        labels.add(r["label"])
        _model_name(path, f"{where}.model", r["model"])
        overrides = _typed(path, f"{where}.overrides", r.get("overrides", {}), dict, "a table")
        per_metric = _typed(path, f"{where}.metric_overrides", r.get("metric_overrides", {}), dict, "a table")
        for m, extra in per_metric.items():
            if m not in metrics:
                raise _err(path, f"{where}.metric_overrides.{m}", f"not a column metric; columns: {', '.join(metrics)}")
            _typed(path, f"{where}.metric_overrides.{m}", extra, dict, "a table of overrides")
        if per_metric and set(per_metric) != set(metrics):
            raise _err(path, f"{where}.metric_overrides", f"must give every column metric: {', '.join(metrics)}")
        noaux = _typed(path, f"{where}.noaux_overrides", r.get("noaux_overrides", {}), dict, "a table")
        settings = [(f"{where}.overrides", overrides)] + [
            (f"{where}.metric_overrides.{m}", {**overrides, **e}) for m, e in per_metric.items()
        ]
        for key, ov in settings + [(f"{where}.noaux_overrides", {**ov, **noaux}) for _, ov in settings if noaux]:
            _config(path, key, r["model"], ov)
        from_table = r.get("from_table")
        if from_table is not None:
            _from_table(
                path, f"{where}.from_table", from_table, r["model"], overrides, per_metric, noaux if no_aux else None
            )
        more = _more_seeds(path, f"{where}.more_seeds", r.get("more_seeds", []))
        rows.append(
            Row(
                r["label"],
                r["model"],
                dict(overrides),
                dict(per_metric),
                from_table=from_table,
                noaux_overrides=noaux,
                more_seeds=more,
            )
        )
    return tuple(rows)


def _more_seeds(path: Path, key: str, raw) -> tuple[MoreSeeds, ...]:
    """A row's `more_seeds`: a list of {profile, difficulty, aux, seeds}, each naming a profile of
    reproduce/profiles.toml, a difficulty of DIFFICULTIES and distinct non-negative integer seeds."""
    from emml.config.profiles import load_profiles

    raw = _typed(path, key, raw, list, "a list of tables {profile, difficulty, aux, seeds}")
    profiles = sorted(load_profiles())
    out = []
    for i, entry in enumerate(raw):
        where = f"{key}[{i}]"
        entry = _section(path, where, entry, MORE_SEEDS_KEYS)
        if entry["profile"] not in profiles:
            raise _err(
                path, f"{where}.profile", f"{entry['profile']!r} is not allowed; choose one of {', '.join(profiles)}"
            )
        if entry["difficulty"] not in DIFFICULTIES:
            raise _err(
                path,
                f"{where}.difficulty",
                f"{entry['difficulty']!r} is not allowed; choose from {', '.join(DIFFICULTIES)}",
            )
        aux = _typed(path, f"{where}.aux", entry["aux"], bool, "true or false")
        seeds = _typed(path, f"{where}.seeds", entry["seeds"], list, "a list of seeds")
        if not seeds or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds):
            raise _err(path, f"{where}.seeds", f"must be a non-empty list of non-negative integers, got {seeds!r}")
        if len(set(seeds)) != len(seeds):
            raise _err(path, f"{where}.seeds", f"a seed appears twice in {seeds!r}")
        out.append(MoreSeeds(entry["profile"], entry["difficulty"], aux, tuple(seeds)))
    return tuple(out)


def _from_table(path: Path, key: str, name, model: str, overrides: dict, per_metric: dict, noaux: dict | None) -> None:
    """A row borrowing another table's runs names a table with a row, itself not borrowing, that trains this very
    setting (``noaux``: its No Aux overrides, None when the borrowing table has no No Aux column)."""
    tables = [t for t in list_tables() if t != path.stem]
    if name not in tables:
        raise _err(path, key, f"{name!r} is not allowed; choose one of {', '.join(tables)}")
    if per_metric:
        raise _err(path, key, "only a plain row may borrow (no metric_overrides)")
    if not any(
        r.model == model
        and r.overrides == overrides
        and (noaux is None or r.noaux_overrides == noaux)
        and not r.metric_overrides
        and not r.from_table  # a row that trains its runs: no chain of borrowing
        for r in load_table(name).rows
    ):
        raise _err(
            path,
            key,
            f"{name} has no row of model {model!r} with overrides {overrides}"
            + (f" and noaux_overrides {noaux}" if noaux is not None else "")
            + " that trains its own runs (not borrowing them) to borrow",
        )


def _parse_transfer(path: Path, data: dict) -> tuple[Transfer, str]:
    """The [transfer] section, and the dataset its training runs use."""
    from emml.eval.transfer import DETECTORS

    raw = _section(path, "transfer", data["transfer"], TRANSFER_KEYS)
    model = _model_name(path, "transfer.model", _typed(path, "transfer.model", raw["model"], str, "a string"))
    overrides = _typed(path, "transfer.overrides", raw["overrides"], dict, "a table")
    cfg = _config(path, "transfer.overrides", model, overrides)
    words = _typed(path, "transfer.words", raw["words"], list, "a list of words")
    if not words or not all(isinstance(w, str) for w in words) or len(set(words)) != len(words):
        raise _err(path, "transfer.words", f"must be a non-empty list of distinct words, got {words!r}")
    detector = _typed(path, "transfer.detector", raw["detector"], str, "a string")
    if detector not in DETECTORS:
        raise _err(path, "transfer.detector", f"{detector!r} is not allowed; choose one of {', '.join(DETECTORS)}")
    return Transfer(model, dict(overrides), tuple(words), detector), cfg.env.dataset


def _parse_transfer_rows(path: Path, data: dict, transfer: Transfer, dataset: str) -> tuple[Row, ...]:
    """Rows of instruction types: every SGN test instruction holding a new word in exactly one row."""
    from emml.tasks.language import load_dataset

    test = load_dataset(dataset).select("sgn", "test")
    wanted = {s.text for s in test if set(s.text.split()) & set(transfer.words)}
    raw = _typed(path, "rows", data.get("rows", []), list, "an array of tables ([[rows]])")
    rows, seen = [], {}
    for i, r in enumerate(raw):
        where = f"rows[{i}]"
        r = _section(path, where, r, TRANSFER_ROW_KEYS, required=("label", "instructions"))
        label = _typed(path, f"{where}.label", r["label"], str, "a string")
        if any(row.label == label for row in rows):
            raise _err(path, f"{where}.label", f"{label!r} appears twice")
        texts = _typed(path, f"{where}.instructions", r["instructions"], list, "a list of instructions")
        if not texts:
            raise _err(path, f"{where}.instructions", "must not be empty")
        for text in texts:
            if text not in wanted:
                raise _err(
                    path,
                    f"{where}.instructions",
                    f"{text!r} is not an SGN test instruction with a new word ({', '.join(transfer.words)})",
                )
            if text in seen:
                raise _err(path, f"{where}.instructions", f"{text!r} is already in row {seen[text]!r}")
            seen[text] = label
        extra = _typed(path, f"{where}.extra", r.get("extra", False), bool, "true or false")
        rows.append(Row(label, transfer.model, dict(transfer.overrides), instructions=tuple(texts), extra=extra))
    missing = sorted(wanted - set(seen))
    if missing:
        raise _err(path, "rows", f"every test instruction with a new word needs a row; missing: {missing}")
    return tuple(rows)


def _check_runs(path: Path, table: Table) -> None:
    """Two settings of one table may not share a run name (an override outside the name's fields would collide)."""
    seen: dict[str, tuple] = {}
    paper = resolve_profile("paper")
    for spec in table.runs([0]):
        name = spec.run_name(paper)
        setting = (spec.row, sorted(spec.overrides.items()))
        if name in seen and seen[name] != setting:
            raise _err(path, "rows", f"rows {seen[name][0]!r} and {spec.row!r} give the same run name {name!r}")
        seen[name] = setting
