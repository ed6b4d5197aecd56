"""The pre-run checks, one step (`prepare`), called where a run starts (`emml train`, `emml demo`, `emml run`,
`emml bench train`, the trainer): before any engine, run dir or MLflow run, each failure a ValueError of one line
naming the field, the folder or the store.

In order: each config's values (`TrainConfig.validate`); what it asks of the model registry, plugins loaded, and of
this machine: the model and its options, compile, precision, device (`emml.rl.hardware.check_runnable`); then, for
runs that write, everything they write to: the MLflow store, each run's folder, each results folder and results CSV
(`emml.runs.preflight.check_train`)."""

from __future__ import annotations

from emml.config.schema import TrainConfig
from emml.rl.hardware import check_runnable


def prepare(*cfgs: TrainConfig, writes: bool = True) -> list[TrainConfig]:
    """``cfgs`` checked before anything starts (see the module); returns them. ``writes``: False for a caller that
    writes no run (`emml bench train`), or whose caller checked what it writes (the trainer, started by those above)."""
    ready = [check_runnable(cfg.validate()) for cfg in cfgs]
    if writes and ready:
        from emml.runs.preflight import check_train

        check_train(*ready)
    return ready
