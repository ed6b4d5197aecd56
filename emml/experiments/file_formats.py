"""The formats of reproduce/'s table and campaign files, declared: a table (reproduce/tableN.toml,
reproduce/experiments/*.toml, one's own) and a campaign (reproduce/campaigns/*.toml); the claims file's is beside its
kinds (emml/experiments/claims/claim_format.py). Each key, its type and its choices are declared once and checked by
the one checker of the project's TOML files (emml/config/toml_files.py, `check_file`): an unknown key, a missing one,
a value of the wrong type or not among its choices fails with the file, the key path and the allowed keys or values,
before any compute. The loaders (emml/experiments/tables.py, campaign/file.py) read a file once it holds to its
format, and check what needs more than the file (the model registry, the profiles, another table's rows, the run
names)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import AfterValidator, Field

from emml.config.env_kinds import ENV_KINDS
from emml.config.schema import TrainConfig
from emml.config.toml_files import Section
from emml.eval.metrics import METRICS, TRANSFER_METRICS

DIFFICULTIES = tuple(ENV_KINDS)
"""Columns of a table: the Doom difficulties, and the House domain (Table 5, Appendix C): emml/config/env_kinds.py."""
STATUSES = ("active", "placeholder")
"""A table's status: it declares runs, or it is completed by its own issue (no runs)."""


def _distinct(values: list) -> list:
    duplicated = sorted({repr(v) for v in values if values.count(v) > 1})
    if duplicated:
        raise ValueError(f"{', '.join(duplicated)} appears twice in {values!r}")
    return values


Text = Annotated[str, "a string"]
Name = Annotated[str, Field(min_length=1), "a non-empty string"]
Overrides = Annotated[dict[str, Any], "a table of overrides (dotted TrainConfig field = value)"]
Flag = Annotated[bool, "true or false"]
Number = Annotated[float, "a number"]


# --- a table (emml/experiments/tables.py) ---------------------------------------------------------------------------
class Columns(Section):
    """[columns]: the table's columns, difficulties × aux × metrics."""

    difficulties: Annotated[list[Literal[DIFFICULTIES]], Field(min_length=1), "a non-empty list of difficulties"]
    aux: Annotated[list[bool], Field(min_length=1), "a non-empty list of booleans"]
    metrics: Annotated[dict[str, Literal[METRICS]], Field(min_length=1), "a non-empty table of label = results column"]


class TransferColumns(Columns):
    """[columns] of a transfer table (Table 4): its cells read the transfer's metrics."""

    metrics: Annotated[
        dict[str, Literal[TRANSFER_METRICS]], Field(min_length=1), "a non-empty table of label = results column"
    ]


Seeds = Annotated[
    list[Annotated[int, Field(ge=0)]],
    Field(min_length=1),
    AfterValidator(_distinct),
    "a non-empty list of non-negative integers",
]


class MoreSeedsEntry(Section):
    """One entry of a row's `more_seeds`: seeds one setting trains beyond its profile's."""

    profile: Text
    """A profile of reproduce/profiles.toml (the loader checks which)."""
    difficulty: Literal[DIFFICULTIES]
    aux: Flag
    seeds: Seeds


class RowEntry(Section):
    """One [[rows]] of a table: a model, with the overrides of its runs."""

    label: Text
    model: Text
    """A model of the registry (`emml models`; the loader checks which)."""
    overrides: Overrides = {}
    metric_overrides: Annotated[dict[str, Overrides], "a table of column metric = overrides"] = {}
    noaux_overrides: Overrides = {}
    from_table: Text | None = None
    more_seeds: Annotated[list[MoreSeedsEntry], "a list of tables {profile, difficulty, aux, seeds}"] = []


class TransferSection(Section):
    """[transfer]: a transfer table's one training setting and what is appended after it (§5.4)."""

    model: Text
    overrides: Overrides
    words: Annotated[list[Name], Field(min_length=1), AfterValidator(_distinct), "a non-empty list of distinct words"]
    detector: Text
    """A detector kind (emml.eval.transfer.DETECTORS; the loader checks which, without importing torch here)."""


class TransferRowEntry(Section):
    """One [[rows]] of a transfer table: an instruction type, the test instructions its cells average over."""

    label: Text
    instructions: Annotated[list[Text], Field(min_length=1), "a non-empty list of instructions"]
    extra: Flag = False


class TableFile(Section):
    """A table file: the paper's table as data (a placeholder declares no columns and no rows)."""

    title: Text
    paper_label: Text
    status: Literal[STATUSES]
    row_header: Text = "Model"
    columns: Columns | None = None
    rows: Annotated[list[RowEntry], "an array of tables ([[rows]])"] = []


class TransferTableFile(TableFile):
    """A transfer table file (Table 4): a [transfer] section, and rows of instruction types."""

    columns: TransferColumns | None = None
    rows: Annotated[list[TransferRowEntry], "an array of tables ([[rows]])"] = []
    transfer: TransferSection


def table_format(data: dict) -> type[TableFile]:
    """The format a table file's data is held to: a transfer table's when it has a [transfer] section."""
    return TransferTableFile if isinstance(data, dict) and "transfer" in data else TableFile


# --- a campaign (emml/experiments/campaign/file.py) -----------------------------------------------------------------
OWN_KEYS = ("frames", "run_root", "results_root")
"""RUNTIME fields a step may not `set`: its `frames` key sets the first; the campaign's options own the roots."""
SETTABLE = tuple(name for name in TrainConfig.RUNTIME if name not in OWN_KEYS)
"""What a step's `set` may hold: how a run is measured and run (TrainConfig.RUNTIME less OWN_KEYS), never what it
is (its name and results row stay the table's)."""


class StepEntry(Section):
    """One [[steps]] of a campaign: some runs of one table under one profile."""

    name: Name
    table: Name
    """A table of reproduce/ (the loader checks which)."""
    profile: Name
    """A profile of reproduce/profiles.toml (the loader checks which)."""
    only: Annotated[dict[str, Any], "a table of run fields = value or list of values"] = {}
    frames: Annotated[int, Field(ge=1), "a positive integer"] | None = None
    set: Annotated[dict[Literal[SETTABLE], Any], "a table of TrainConfig.RUNTIME fields = value"] = {}
    claim: Annotated[Text | list[Text], "a claim id or a list of them"] = []
    note: Text = ""


class CampaignFile(Section):
    """A campaign file: its title and its steps, in training order."""

    title: Text | None = None
    steps: Annotated[list[StepEntry], Field(min_length=1), "a non-empty array of tables ([[steps]])"]
