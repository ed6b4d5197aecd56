"""The results tables: results/<table>/<profile>.csv, one row per finished run, with its provenance.

Every column's type is declared here, for the writer and every reader: pandas' type inference turns a git sha
such as ``12e0077`` into the float 1.2e+78, and provenance that cannot be read back is provenance lost.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import pandas as pd

from emml.runs.atomic import replacing
from emml.runs.records import note, torn_tail
from emml.runs.runlock import waiting_lock

# identity and provenance columns (read as written); every other column is a metric (float). started_at, ended_at
# and segments are results.json's (emml.runs.rundir.TIMES, JSON_ONLY), not written to rows: declared so that a row
# that has them (written by code from before them, which copies every key of results.json) reads
TEXT = (
    "run_name",
    "table",
    "model",
    "difficulty",
    "profile",
    "git_sha",
    "scored_sha",
    "run_id",
    "tasks",
    "precision",
    "transfer_words",
    "transfer_detector",
    "started_at",
    "ended_at",
    "segments",
)
INTEGER = ("seed", "frames", "eval_episodes")
LATE_INTEGER = ("eval_seed",)
"""Integer columns added after rows were written: empty in older rows (read as missing), and written as floats
('10000.0') by code from before them, which reads an unknown column as a metric."""
BOOLEAN = ("aux", "shaping")
_BOOL = {"True": True, "False": False, "true": True, "false": False}


def read_results(path: str | Path) -> pd.DataFrame:
    """A results CSV with every column typed as declared (an empty frame with a run_name column if absent)."""
    path = Path(path)
    if not path.exists():
        return pd.DataFrame({"run_name": pd.Series(dtype=str), "run_id": pd.Series(dtype=str)})
    df = _read_csv(path)
    for col in df.columns:
        if col in TEXT:
            continue
        if col in INTEGER:
            df[col] = _convert(df[col], int, "an integer", path, col)
        elif col in LATE_INTEGER:
            df[col] = _convert(df[col], _late_int, "an integer", path, col).astype("Int64")
        elif col in BOOLEAN:
            df[col] = _convert(df[col], _BOOL.__getitem__, "True or False", path, col)
        else:
            df[col] = _convert(df[col], lambda v: float(v) if v else float("nan"), "a number", path, col)
    return df


def _late_int(value: str):
    if not value:
        return pd.NA
    number = float(value)
    if not number.is_integer():
        raise ValueError(f"{value!r}")
    return int(number)


class ResultsError(ValueError):
    """A results CSV that cannot be read as one (the message names the file and the line)."""


def _read_csv(path: Path) -> pd.DataFrame:
    """Every cell as text; a file that is not a well-formed CSV fails naming it and the line."""
    try:
        data = path.read_bytes()
    except OSError as e:
        raise ResultsError(f"{path}: cannot be read ({e.strerror})") from None
    data = _whole_rows(path, data)
    try:
        df = pd.read_csv(io.BytesIO(data), dtype=str, keep_default_na=False)
    except UnicodeDecodeError:
        raise ResultsError(f"{path}: {_first_non_utf8(path)}: not UTF-8 text") from None
    except pd.errors.EmptyDataError:
        raise ResultsError(f"{path}: empty, without the header line a results CSV starts with") from None
    except pd.errors.ParserError as e:  # pandas names the line: "Expected 3 fields in line 7, saw 4"
        why = str(e).strip().removeprefix("Error tokenizing data. C error: ")
        raise ResultsError(f"{path}: not a well-formed CSV: {why}") from None
    if "run_name" not in df.columns:
        raise ResultsError(f"{path}: line 1: no 'run_name' column in the header (found {', '.join(df.columns)})")
    return df


def _whole_rows(path: Path, data: bytes) -> bytes:
    """``data`` less a torn last row (one cut short by a kill or a full disk: no newline, fewer fields than the
    header), with a one-line note; the file itself is rewritten whole by the next `upsert_result`. A last row without
    its newline but with every field is whole."""
    keep = torn_tail(data)
    if keep == len(data) or keep == 0:
        return data
    header = next(csv.reader([data.split(b"\n", 1)[0].decode("utf-8", errors="replace")]), [])
    last = next(csv.reader([data[keep:].decode("utf-8", errors="replace")]), [])
    if len(last) >= len(header):
        return data
    line = data[:keep].count(b"\n") + 1
    note(
        f"{path}: line {line} was cut short ({len(last)} of {len(header)} fields: a write "
        "interrupted by a kill or a full disk); read up to the last whole row"
    )
    return data[:keep]


def _first_non_utf8(path: Path) -> str:
    """'line N' of the first line of ``path`` that is not UTF-8 (pandas reports a position in its buffer)."""
    for n, line in enumerate(path.read_bytes().split(b"\n"), 1):
        try:
            line.decode("utf-8")
        except UnicodeDecodeError:
            return f"line {n}"
    return "a line"


def _convert(values: pd.Series, cast, what: str, path: Path, col: str) -> pd.Series:
    try:
        return values.map(cast)
    except (KeyError, ValueError):
        for i, value in enumerate(values):  # the first bad cell; line 1 is the header
            try:
                cast(value)
            except (KeyError, ValueError):
                raise ResultsError(f"{path}: line {i + 2}: column {col!r} must hold {what}, found {value!r}") from None
        raise


def upsert_result(path: str | Path, row: dict) -> Path:
    """Replace (or add) the row with this run_name, sorted by run_name, written atomically.

    Runs of one table finish in parallel processes: an exclusive lock on a side file serialises the
    read-modify-write, so that no row is lost."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with waiting_lock(path.with_suffix(".csv.lock")):
        table = read_results(path)
        table = table[table["run_name"] != row["run_name"]]
        new = pd.DataFrame([{k: str(v) if k in TEXT else v for k, v in row.items()}])
        table = pd.concat([table, new], ignore_index=True) if not table.empty else new
        with replacing(path) as tmp:
            table.sort_values("run_name").to_csv(tmp, index=False)
    return path
