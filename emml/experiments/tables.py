"""Reading a table file: reproduce/tableN.toml (or an experiment's, or one's own) → a checked `Table`
(emml/experiments/table_data.py), whose `runs` are the `RunSpec`s to train (one per setting and seed).

A table file reads like the paper's table (Chaplot et al. 2019, arXiv:1902.01385): `[[rows]]` are its rows (a
model, optionally with config overrides), `[columns]` its columns (difficulties × aux × metrics). Each
(row, difficulty, aux) is a *setting*; a setting is trained once per seed of the profile (reproduce/profiles.toml).
A row with `metric_overrides` trains one setting per metric (Table 3's "DA Single-Task": SGN cells from SGN-only
runs, EQA cells from EQA-only runs). Run names derive from the config (`emml.runs.naming.run_name`), and two runs of a
table may not share one. This module declares the keys and values a file may hold and checks each: a malformed file
fails with the file, the key and what is wrong: its keys, types and choices are declared in
emml/experiments/file_formats.py and checked first, then what needs more than the file (the model registry, the
profiles, the tables it borrows from, the run names) here. A table is checked once per content (`LOADED`).
"""

from __future__ import annotations

from pathlib import Path

import tomllib

from emml.config.profiles import resolve_profile
from emml.config.schema import TrainConfig, apply_overrides
from emml.config.toml_files import FileError, check_file
from emml.experiments.file_formats import DIFFICULTIES as DIFFICULTIES  # the columns (also imported from here)
from emml.experiments.file_formats import table_format
from emml.experiments.runspec import Transfer
from emml.experiments.table_data import MoreSeeds, Row, Table
from emml.experiments.table_files import find_table, list_tables, table_path


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


_err = FileError
"""A table file's error: the file, the key path, what is wrong (the one dialect of emml/config/toml_files.py)."""


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


def _parse(name: str, path: Path, data: dict) -> Table:
    """The table of a file's data: held to its format (emml/experiments/file_formats.py), then checked against the
    model registry, the profiles, the tables it borrows from and its run names."""
    check_file(path, data, table_format(data))
    common = dict(
        name=name,
        path=path,
        title=data["title"],
        paper_label=data["paper_label"],
        status=data["status"],
        row_header=data.get("row_header", "Model"),
    )
    if data["status"] == "placeholder":
        for key in ("rows", "columns"):
            if key in data:
                raise _err(path, key, "a placeholder table declares no runs; set status = 'active' to add them")
        return Table(**common)
    if "transfer" in data:
        columns = _parse_columns(path, data)
        transfer, dataset = _parse_transfer(path, data)
        rows = _parse_transfer_rows(path, data, transfer, dataset)
        table = Table(**common, rows=rows, transfer=transfer, **columns)
    else:
        columns = _parse_columns(path, data)
        rows = _parse_rows(path, data, tuple(columns["metrics"].values()), no_aux=False in columns["aux"])
        table = Table(**common, rows=rows, **columns)
    _check_runs(path, table)
    return table


def _parse_columns(path: Path, data: dict) -> dict:
    """The [columns] (their values checked by the format)."""
    if "columns" not in data:
        raise _err(path, "columns", "missing: an active table needs [columns] difficulties, aux, metrics")
    cols = data["columns"]
    return {"difficulties": tuple(cols["difficulties"]), "aux": tuple(cols["aux"]), "metrics": dict(cols["metrics"])}


def _parse_rows(path: Path, data: dict, metrics: tuple[str, ...], no_aux: bool = True) -> tuple[Row, ...]:
    """The rows; ``no_aux``: the table has runs without the auxiliary task (else `noaux_overrides` play no part)."""
    raw = data.get("rows", [])
    if not raw:
        raise _err(path, "rows", "an active table needs at least one [[rows]]")
    rows, labels = [], set()
    for i, r in enumerate(raw):
        where = f"rows[{i}]"
        if r["label"] in labels:
            raise _err(path, f"{where}.label", f"{r['label']!r} appears twice")
        labels.add(r["label"])
        _model_name(path, f"{where}.model", r["model"])
        overrides = r.get("overrides", {})
        per_metric = r.get("metric_overrides", {})
        for m in per_metric:
            if m not in metrics:
                raise _err(path, f"{where}.metric_overrides.{m}", f"not a column metric; columns: {', '.join(metrics)}")
        if per_metric and set(per_metric) != set(metrics):
            raise _err(path, f"{where}.metric_overrides", f"must give every column metric: {', '.join(metrics)}")
        noaux = r.get("noaux_overrides", {})
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
    """A row's `more_seeds` (its entries' keys and values checked by the format), each naming a profile of
    reproduce/profiles.toml."""
    from emml.config.profiles import load_profiles

    profiles = sorted(load_profiles())
    out = []
    for i, entry in enumerate(raw):
        if entry["profile"] not in profiles:
            raise _err(
                path, f"{key}[{i}].profile", f"{entry['profile']!r} is not allowed; choose one of {', '.join(profiles)}"
            )
        out.append(MoreSeeds(entry["profile"], entry["difficulty"], entry["aux"], tuple(entry["seeds"])))
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

    raw = data["transfer"]
    model = _model_name(path, "transfer.model", raw["model"])
    overrides, words, detector = raw["overrides"], raw["words"], raw["detector"]
    cfg = _config(path, "transfer.overrides", model, overrides)
    if detector not in DETECTORS:
        raise _err(path, "transfer.detector", f"{detector!r} is not allowed; choose one of {', '.join(DETECTORS)}")
    return Transfer(model, dict(overrides), tuple(words), detector), cfg.env.dataset


def _parse_transfer_rows(path: Path, data: dict, transfer: Transfer, dataset: str) -> tuple[Row, ...]:
    """Rows of instruction types: every SGN test instruction holding a new word in exactly one row."""
    from emml.tasks.language import load_dataset

    test = load_dataset(dataset).select("sgn", "test")
    wanted = {s.text for s in test if set(s.text.split()) & set(transfer.words)}
    rows, seen = [], {}
    for i, r in enumerate(data.get("rows", [])):
        where = f"rows[{i}]"
        label, texts = r["label"], r["instructions"]
        if any(row.label == label for row in rows):
            raise _err(path, f"{where}.label", f"{label!r} appears twice")
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
        extra = r.get("extra", False)
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
