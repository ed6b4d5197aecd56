"""Reading a table file: reproduce/tableN.toml (or an experiment's, or one's own) → a checked `Table`
(emml/experiments/table_data.py), whose `runs` are the `RunSpec`s to train (one per setting and seed).

A table file reads like the paper's table (Chaplot et al. 2019, arXiv:1902.01385): `[[rows]]` are its rows (a
model, optionally with config overrides), `[columns]` its columns (difficulties × aux × metrics). Each
(row, difficulty, aux) is a *setting*; a setting is trained once per seed of the profile (reproduce/profiles.toml).
A row with `metric_overrides` trains one setting per metric (Table 3's "DA Single-Task": SGN cells from SGN-only
runs, EQA cells from EQA-only runs). Run names derive from the config (`emml.runs.naming.run_name`), and two runs of a
table may not share one. This module declares the keys and values a file may hold and checks each: a malformed file
fails with the file, the key and what is wrong. A table is checked once per content (`LOADED`).
"""

from __future__ import annotations

from pathlib import Path

import tomllib

from emml.config.env_kinds import ENV_KINDS
from emml.config.profiles import resolve_profile
from emml.config.schema import TrainConfig, apply_overrides
from emml.eval.metrics import METRICS, TRANSFER_METRICS
from emml.experiments.runspec import Transfer
from emml.experiments.table_data import MoreSeeds, Row, Table
from emml.experiments.table_files import find_table, list_tables, table_path

STATUSES = ("active", "placeholder")
DIFFICULTIES = tuple(ENV_KINDS)
"""Columns of a table: the Doom difficulties, and the House domain (Table 5, Appendix C): emml/config/env_kinds.py."""
TOP_KEYS = ("title", "paper_label", "status", "row_header", "columns", "rows", "transfer")
COLUMN_KEYS = ("difficulties", "aux", "metrics")
ROW_KEYS = ("label", "model", "overrides", "metric_overrides", "noaux_overrides", "from_table", "more_seeds")
MORE_SEEDS_KEYS = ("profile", "difficulty", "aux", "seeds")
TRANSFER_KEYS = ("model", "overrides", "words", "detector")
TRANSFER_ROW_KEYS = ("label", "instructions", "extra")


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
