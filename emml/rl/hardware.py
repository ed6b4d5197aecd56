"""What this installation and this machine can run of a run's config, checked where training starts
(`check_runnable`), part of the one pre-run step (`emml.rl.prepare.prepare`): by the trainer before any compute,
and by `emml train`, `emml run` and `emml bench train` before any run starts.

`TrainConfig.validate` checks the values (it is a leaf and imports no torch); these are the checks that ask the model
registry (the model's name and options, plugins loaded: `emml.models.model_config`) and the machine: a C++ compiler
for `compile='on'` on a CPU (emml/models/compiled.py), native bf16 arithmetic for `precision='bf16'`
(emml/rl/precision.py), a CUDA device for `device='cuda'`. Each failure is a ValueError naming the field, its value
and what to use instead (the CLI prints it and exits 2).
"""

from __future__ import annotations

import torch

from emml.config.schema import TrainConfig
from emml.models import model_config
from emml.models.compiled import check_compile
from emml.rl.precision import check_precision


def check_device(device: str) -> None:
    """Refuse, before any compute, a CUDA device torch cannot see."""
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise ValueError(f"device={device!r} but torch sees no CUDA device; use device='cpu'")


def check_hardware(cfg: TrainConfig) -> TrainConfig:
    """Refuse, before any compute, what this machine cannot run of ``cfg`` (validated): its compile, device and
    precision settings; returns ``cfg``."""
    check_compile(cfg.compile, cfg.device)
    check_device(cfg.device)
    check_precision(cfg.precision, cfg.device)
    return cfg


def check_runnable(cfg: TrainConfig) -> TrainConfig:
    """Refuse, before any compute, what ``cfg`` (validated) asks of the model registry or of this machine that they
    cannot give: an unknown model or model option, or a compile, device or precision setting; returns ``cfg``."""
    model_config(cfg.model, **cfg.model_options)  # names an unknown model or option, a bad value
    return check_hardware(cfg)
