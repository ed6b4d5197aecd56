"""The paper's claims as data (reproduce/claims.toml): each one the comparison of table cells that decides it.
Each claim's `kind` is an object of emml/experiments/claims/kinds.py (the fields it needs, its rule, its decision).

The campaign's steps name the claims their runs decide (emml/experiments/campaign/progress.py, `--status`); the
reports state each claim beside the cells that decide it. Loading holds the file to its format
(emml/experiments/claims/claim_format.py: keys, types, kinds, marks), then checks every claim against its table (rows,
metrics, columns), before any compute, with errors that name the file, the claim and the allowed values.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from emml.config.paths import REPRODUCE_DIR
from emml.config.toml_files import check_file, read_toml
from emml.eval.metrics import CURVE_METRICS, metric, train_of
from emml.experiments.claims.claim_format import MARKS, ClaimsFile
from emml.experiments.claims.kinds import KINDS
from emml.experiments.tables import load_table

CLAIMS_FILE = REPRODUCE_DIR / "claims.toml"


@dataclass(frozen=True)
class Claim:
    """One claim of the paper and the cells that decide it."""

    id: str
    """Short name (campaign steps and reports refer to it)."""
    text: str
    """The claim in a sentence."""
    source: str
    """Where the paper makes it (section, table, its numbers)."""
    kind: str
    """One of KINDS."""
    table: str
    """The table whose cells decide it (reproduce/<table>.toml)."""
    rows: tuple[str, ...]
    """The rows compared: `row` for 'best'; the ablations for 'below' and 'level'; every row of the table when the
    file names none ('at_least', 'aux_helps')."""
    metrics: tuple[str, ...]
    """The results columns compared (sgn_test, eqa_test, ...)."""
    where: dict = field(default_factory=dict)
    """RunSpec fields fixing the table's columns (difficulty, aux); a field absent: every value of it."""
    than: str | None = None
    """The reference row of 'below' and 'level'."""
    margin: float | None = None
    """'level': the largest difference that still counts as level (ours: the paper says 'little effect')."""
    value: float | None = None
    """'at_least' and 'diagnostic': the threshold."""
    mark: str | None = None
    """'faster': the crossing compared, one of MARKS."""
    key: str | None = None
    """'diagnostic': the metrics.csv key read (diag/detector_ap, ...)."""
    relative: dict = field(default_factory=dict)
    """'diagnostic': RunSpec fields of a reference setting (e.g. aux = true): the threshold is `value` times the same
    row's mean there; empty: `value` itself."""
    inferred: bool = False
    """The paper does not state it in a sentence: we read it from its table (the page says so)."""
    on_paper: str = ""
    """Why the paper's own table fails the claim's rule, where it does (the page shows the paper's decision; a test
    checks that exactly these claims fail on the paper's numbers)."""

    @property
    def kind_of(self):
        """The kind as an object (emml/experiments/claims/kinds.py)."""
        return KINDS[self.kind]


def load_claims(path: Path = CLAIMS_FILE) -> dict[str, Claim]:
    """Every claim of the file by id, held to the file's format, then checked against its table."""
    try:
        data = read_toml(path)
    except OSError as e:
        raise ValueError(f"{path}: cannot be read: {e}") from None
    check_file(path, data, ClaimsFile)
    claims: dict[str, Claim] = {}
    for i, raw in enumerate(data["claims"]):
        where = f"{path}: claims[{i}]"
        if raw["id"] in claims:
            raise ValueError(f"{where}: id={raw['id']!r} is used twice; ids must be unique")
        claims[raw["id"]] = _claim(where, raw)
    return claims


def _claim(where: str, raw: dict) -> Claim:
    try:
        table = load_table(raw["table"])
    except ValueError as e:  # issue 65: the file and the key path named ('…: claims[0].table: 'table9' is unknown…')
        unknown = f"table={raw['table']!r} "
        said = str(e)
        raise ValueError(
            f"{where}.table: {said.removeprefix('table=')}" if said.startswith(unknown) else f"{where}.table: {said}"
        ) from None
    labels = [r.label for r in table.rows]
    kind = raw["kind"]
    for key in KINDS[kind].needs:
        if key not in raw:
            raise ValueError(f"{where}: kind={kind!r} needs {key!r}")
    k = KINDS[kind]
    crossing = [n for n, x in KINDS.items() if x.reads == "crossing"]
    mark = raw.get("mark", "chance" if k.reads == "crossing" else None)
    if mark is not None and (k.reads != "crossing" or mark not in MARKS):
        allowed = ", ".join(MARKS) if k.reads == "crossing" else f"kind={'/'.join(crossing)!r} only"
        raise ValueError(f"{where}.mark={mark!r} is not allowed; allowed: {allowed}")
    figure = "/".join(n for n, x in KINDS.items() if x.reads == "figure")
    if "key" in raw and (k.reads != "figure" or not str(raw["key"]).startswith("diag/")):
        raise ValueError(f"{where}.key={raw['key']!r}: kind={figure!r} only, a metrics.csv key diag/<name>")
    rows = (raw["row"],) if k.one_row else tuple(raw.get("rows", labels))
    for label in [*rows, *([raw["than"]] if "than" in raw else [])]:
        if label not in labels:
            raise ValueError(f"{where}: row {label!r} is not a row of {raw['table']}; allowed: {', '.join(labels)}")
    metrics = tuple(raw.get("metrics", list(table.metrics.values())[:1]))  # diagnostic: the cell whose runs it reads
    columns = table.metrics.values()
    # a test column's train twin, read from the same runs' rows
    trains = [train_of(metric(m).task).name for m in columns if metric(m).split == "test"]
    allowed = tuple(dict.fromkeys([*columns, *trains, *(CURVE_METRICS if k.reads == "crossing" else ())]))
    for m in metrics:
        if m not in allowed:
            raise ValueError(f"{where}.metrics: {m!r} is not a column of {raw['table']}; allowed: {', '.join(allowed)}")
    if k.metric_count is not None and len(metrics) != k.metric_count:
        raise ValueError(
            f"{where}.metrics={list(metrics)!r}: kind={kind!r} compares {k.metric_count}, the harder task's first"
        )
    cells = dict(raw.get("where", {}))
    relative = dict(raw.get("relative", {}))
    if relative and k.reads != "figure":
        raise ValueError(f"{where}.relative: kind={figure!r} only")
    for part, selection in (("where", cells), ("relative", relative)):
        for key, value in selection.items():
            values = table.difficulties if key == "difficulty" else table.aux
            if value not in values:
                raise ValueError(f"{where}.{part}.{key}={value!r} is not a column of {raw['table']}; allowed: {values}")
    return Claim(
        raw["id"],
        raw["text"],
        raw["source"],
        kind,
        raw["table"],
        rows,
        metrics,
        cells,
        raw.get("than"),
        raw.get("margin"),
        raw.get("value"),
        mark,
        raw.get("key"),
        relative,
        bool(raw.get("inferred", False)),
        str(raw.get("on_paper", "")),
    )
