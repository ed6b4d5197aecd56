"""One training run of a table (`RunSpec`: a setting and a seed) and what a transfer table's runs append after
training (`Transfer`). A table expands to these (emml/experiments/table_data.py `Table.runs`); the launcher, the
process pool, Slurm, the campaigns and the report pass them around, and each turns into its TrainConfig and run name
here."""

from __future__ import annotations

from dataclasses import dataclass, field

from emml.config.profiles import Profile, resolve_profile
from emml.config.schema import TrainConfig
from emml.runs.naming import run_name


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
