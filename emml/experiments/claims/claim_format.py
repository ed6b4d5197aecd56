"""The format of the claims file (reproduce/claims.toml), declared: each key of a claim, its type and its choices (a
kind of emml/experiments/claims/kinds.py, a mark), checked by the one checker of the project's TOML files
(emml/config/toml_files.py, `check_file`) before emml/experiments/claims/claim.py checks each claim against its
table (rows, metrics, columns)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from emml.config.toml_files import Section
from emml.experiments.claims.kinds import KINDS
from emml.experiments.file_formats import DIFFICULTIES, Flag, Number, Text

MARKS = ("chance", "0.5", "0.9")
"""A 'faster' claim's crossing: leaving chance, reaching 0.5, reaching 0.9 (emml/report/efficiency.py)."""


class WhereEntry(Section):
    """A claim's `where` or `relative`: RunSpec fields fixing the table's columns (the loader checks the values
    against the table's columns)."""

    difficulty: Literal[DIFFICULTIES] | None = None
    aux: Flag | None = None


class ClaimEntry(Section):
    """One [[claims]]: a claim of the paper and the cells that decide it (what each key means: `Claim`)."""

    id: Text
    text: Text
    source: Text
    kind: Literal[tuple(KINDS)]
    table: Text
    row: Text | None = None
    rows: Annotated[list[Text], "a list of row labels"] | None = None
    than: Text | None = None
    where: WhereEntry = WhereEntry()
    metrics: Annotated[list[Text], "a list of results columns"] | None = None
    margin: Number | None = None
    value: Number | None = None
    mark: Literal[MARKS] | None = None
    key: Text | None = None
    relative: WhereEntry = WhereEntry()
    inferred: Flag = False
    on_paper: Text = ""


class ClaimsFile(Section):
    """The claims file: its claims, each with a unique id."""

    claims: Annotated[list[ClaimEntry], Field(min_length=1), "a non-empty array of tables ([[claims]])"]
