import pytest

from emml.config.schema import TrainConfig
from emml.rl.prepare import prepare


def test_one_step_checks_values_then_the_registry_then_what_the_runs_write(tmp_path, monkeypatch):
    """`prepare` (emml/rl/prepare.py), what every run start calls: a bad value is refused before the store is asked,
    an unknown model option before it too, and the store only for runs that write (the trainer and `bench train`
    pass writes=False: their callers checked it, or they write no run)."""
    from emml.runs.preflight import PreflightError

    monkeypatch.setenv("MLFLOW_TRACKING_URI", "sqlite:////proc/mlflow.db")  # a store no run can write to
    roots = {"run_root": str(tmp_path / "runs"), "results_root": str(tmp_path / "results")}
    with pytest.raises(ValueError, match=r"frames=1 is less than one update"):
        prepare(TrainConfig(frames=1, **roots))
    with pytest.raises(ValueError, match=r"nope") as e:
        prepare(TrainConfig(model_options={"nope": 1}, **roots))
    assert not isinstance(e.value, PreflightError)
    cfg = TrainConfig(**roots)
    assert prepare(cfg, writes=False) == [cfg]
    with pytest.raises(PreflightError, match=r"MLflow store sqlite:////proc/mlflow.db: cannot create files in /proc"):
        prepare(cfg)
    assert not (tmp_path / "runs").exists() and not (tmp_path / "results").exists()
