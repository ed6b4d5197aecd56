"""The results tables: results/<table>/<profile>.csv, one row per finished run, with its provenance; and beside
each, results/<table>/<profile>-questions.csv: EQA's successes per question of each run's final evaluation (issue 81),
long format, one row per (run, task, split, question) with the columns `QUESTION_COLUMNS`. Both are written whole
under a lock (`upsert_result`, `upsert_questions`): a writer replaces its own run's rows, never another's.

Every column's type is declared here, for the writer and every reader: pandas' type inference turns a git sha
such as ``12e0077`` into the float 1.2e+78, and provenance that cannot be read back is provenance lost.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import pandas as pd

from emml.config.env import SPLITS
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


# --- per question (issue 81) ---------------------------------------------------------------------------------------
QUESTION_COLUMNS = ("run_name", "run_id", "task", "split", "question", "successes", "episodes")
"""The per-question file's columns: the run (its name, and the training its counts are of: a row whose run_id is not
the results row's is of an earlier training), the setting, the question's text, and its successes of its episodes in
the final evaluation (`emml.eval.evaluate.Scores.questions`)."""
QUESTIONS_SUFFIX = "-questions"
"""results/<table>/<profile>``-questions``.csv: the per-question file beside a results table."""


def questions_path(results: str | Path) -> Path:
    """The per-question file beside the results table ``results`` (<profile>.csv → <profile>-questions.csv)."""
    results = Path(results)
    return results.with_name(f"{results.stem}{QUESTIONS_SUFFIX}.csv")


def read_questions(path: str | Path) -> pd.DataFrame:
    """A per-question file, typed (successes and episodes integers, 0 ≤ successes ≤ episodes); an empty frame with
    `QUESTION_COLUMNS` if absent. ResultsError naming the file (and the line) otherwise."""
    path = Path(path)
    if not path.exists():
        return pd.DataFrame(
            {c: pd.Series(dtype=int if c in ("successes", "episodes") else str) for c in QUESTION_COLUMNS}
        )
    df = _read_csv(path)
    missing = [c for c in QUESTION_COLUMNS if c not in df.columns]
    if missing:
        raise ResultsError(
            f"{path}: line 1: no column {', '.join(map(repr, missing))} (needs {', '.join(QUESTION_COLUMNS)})"
        )
    for col in ("successes", "episodes"):
        df[col] = _convert(df[col], int, "an integer", path, col)
    bad = ~df["successes"].between(0, df["episodes"])
    if bad.any():
        i = int(bad.to_numpy().argmax())
        row = df.iloc[i]
        raise ResultsError(
            f"{path}: line {i + 2}: successes must lie between 0 and episodes, found {row['successes']} of "
            f"{row['episodes']}"
        )
    return df


def question_rows(run_name: str, run_id: str, questions: dict[str, dict[str, dict[str, int]]]) -> pd.DataFrame:
    """The per-question file's rows of one run from `Scores.questions` ({'eqa_test': {question: {'successes': k,
    'episodes': n}}}); a setting not named '<task>_<split>' is a ValueError naming it."""
    rows = []
    for setting, counts in questions.items():
        task, _, split = setting.partition("_")
        if split not in SPLITS:
            raise ValueError(f"questions: setting {setting!r} is not '<task>_<split>' with split 'train' or 'test'")
        for question, c in counts.items():
            rows.append((run_name, str(run_id), task, split, question, int(c["successes"]), int(c["episodes"])))
    return pd.DataFrame(rows, columns=list(QUESTION_COLUMNS))


def upsert_questions(path: str | Path, run_name: str, run_id: str, questions: dict) -> Path:
    """Replace (or add) the rows of run ``run_name`` in the per-question file ``path`` by ``questions``
    (`question_rows`), sorted, written atomically under the file's lock: another run's rows are never lost."""
    path = Path(path)
    new = question_rows(run_name, run_id, questions)
    path.parent.mkdir(parents=True, exist_ok=True)
    with waiting_lock(path.with_suffix(".csv.lock")):
        table = read_questions(path)
        table = table[table["run_name"] != run_name]
        table = pd.concat([table, new], ignore_index=True) if not table.empty else new
        with replacing(path) as tmp:
            table.sort_values(["run_name", "task", "split", "question"]).to_csv(tmp, index=False)
    return path
