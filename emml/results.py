"""The results tables: results/<table>/<profile>.csv, one row per finished run, with its provenance.

Every column's type is declared here, for the writer and every reader: pandas' type inference turns a git sha
such as ``12e0077`` into the float 1.2e+78, and provenance that cannot be read back is provenance lost.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

import pandas as pd

# identity and provenance columns (read as written); every other column is a metric (float)
TEXT = (
    "run_name",
    "table",
    "model",
    "difficulty",
    "profile",
    "git_sha",
    "run_id",
    "tasks",
    "precision",
    "transfer_words",
    "transfer_detector",
)
INTEGER = ("seed", "frames", "eval_episodes")
BOOLEAN = ("aux", "shaping")
_BOOL = {"True": True, "False": False, "true": True, "false": False}


def read_results(path: str | Path) -> pd.DataFrame:
    """A results CSV with every column typed as declared (an empty frame with a run_name column if absent)."""
    path = Path(path)
    if not path.exists():
        return pd.DataFrame({"run_name": pd.Series(dtype=str), "run_id": pd.Series(dtype=str)})
    df = pd.read_csv(path, dtype=str, keep_default_na=False)
    for col in df.columns:
        if col in TEXT:
            continue
        if col in INTEGER:
            df[col] = _convert(df[col], int, "an integer", path, col)
        elif col in BOOLEAN:
            df[col] = _convert(df[col], _BOOL.__getitem__, "True or False", path, col)
        else:
            df[col] = _convert(df[col], lambda v: float(v) if v else float("nan"), "a number", path, col)
    return df


def _convert(values: pd.Series, cast, what: str, path: Path, col: str) -> pd.Series:
    try:
        return values.map(cast)
    except (KeyError, ValueError) as e:
        raise ValueError(f"{path}: column {col!r} must hold {what}, found {e}") from None


def upsert_result(path: str | Path, row: dict) -> Path:
    """Replace (or add) the row with this run_name, sorted by run_name, written atomically.

    Runs of one table finish in parallel processes: an exclusive lock on a side file serialises the
    read-modify-write, so that no row is lost."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path.with_suffix(".csv.lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        table = read_results(path)
        table = table[table["run_name"] != row["run_name"]]
        new = pd.DataFrame([{k: str(v) if k in TEXT else v for k, v in row.items()}])
        table = pd.concat([table, new], ignore_index=True) if not table.empty else new
        tmp = path.with_suffix(f".csv.{os.getpid()}.tmp")
        table.sort_values("run_name").to_csv(tmp, index=False)
        os.replace(tmp, path)
    return path
