"""What this machine can run (emml/rl/hardware.py) is asked where training starts, not by the config: a config
with device='cuda' validates on any machine, and the trainer and `emml run` refuse it by name, before any compute
or run, where torch sees no CUDA device (compile and precision: tests/models/test_compiled.py, test_precision.py)."""

import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from emml.config.profiles import profile_config
from emml.config.schema import TrainConfig
from emml.experiments.launch import run_table
from emml.rl.hardware import check_runnable
from emml.rl.trainer import Trainer

NO_CUDA = re.escape("device='cuda' but torch sees no CUDA device; use device='cpu'")


@pytest.fixture
def no_cuda(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)


def never_train(cfg, quiet=False, parent_run_id=None):
    raise AssertionError("a run started")


def test_cuda_without_a_device_is_refused_where_training_starts(no_cuda, tmp_path):
    cfg = profile_config("smoke", "easy", {"device": "cuda", "run_root": str(tmp_path / "runs")}).validate()
    with pytest.raises(ValueError, match=NO_CUDA):
        check_runnable(cfg)
    with pytest.raises(ValueError, match=NO_CUDA):
        Trainer(cfg)
    assert not (tmp_path / "runs").exists()  # refused before anything was written


def test_the_launcher_refuses_before_any_run(no_cuda, tracking):
    with pytest.raises(ValueError, match=NO_CUDA):
        run_table(
            "table3",
            "smoke",
            run_root=tracking["run_root"],
            results_root=tracking["results_root"],
            device="cuda",
            jobs=1,
            train_fn=never_train,
            log=lambda m: None,
        )
    assert not Path(tracking["run_root"]).exists()


def test_the_config_imports_no_torch_and_no_layer_above_it():
    """The layers contract (pyproject.toml, `make lint`) reads the source; this runs it: `import emml.config.schema`,
    and validating a config with model options (the model registry is asked where training starts, not here)."""
    above = ("torch", "emml.rl", "emml.models", "emml.envs", "emml.tasks", "emml.runs")
    code = (
        "import sys; from emml.config.schema import TrainConfig, ModelConfig, apply_overrides; "
        "apply_overrides(TrainConfig(model='pacman'), {'model_options.pacman_frames': 3}).validate(); "
        "ModelConfig(name='pacman').validate(); "
        f"print([m for m in sys.modules if m.startswith({above})])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_a_model_the_registry_does_not_know_is_refused_where_training_starts():
    cfg = TrainConfig(model="mine").validate()  # a value the configs accept: a registry name is not theirs to check
    with pytest.raises(ValueError, match="unknown model name='mine'.*--plugin"):
        check_runnable(cfg)
    with pytest.raises(ValueError, match="model_options: 'ga1' is not an option of model 'ga'; its options: "):
        check_runnable(TrainConfig(model="ga", model_options={"ga1": False}).validate())  # Dual-Attention's own
    cfg = TrainConfig(model_options={"hiden": 64}).validate()  # a name the configs accept: the model declares its own
    with pytest.raises(ValueError, match="'hiden' is not an option of model 'dual_attention'; its options: embed_dim"):
        check_runnable(cfg)
    with pytest.raises(ValueError, match="model_options: '2x' is not a model option name"):
        TrainConfig(model_options={"2x": 64}).validate()
