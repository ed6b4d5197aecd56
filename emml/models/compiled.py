"""`TrainConfig.compile`: the model's batched parts through `torch.compile`, in place.

The conv stack and the fusion unit run batched over T·B in acting (T = 1) and in the PPO update (T = 128), with
fixed shapes per call site, so they compile once per shape. They are compiled in place (`nn.Module.compile`):
parameter names, checkpoints and hooks stay those of the plain model, and outputs equal it within float tolerance
(tests/models/test_compiled.py). The policy's recurrent loop is left alone: compiling the whole model, its 128 unrolled
steps included, took 180 s for the same update time as the pieces (docs/throughput.md).

On a CPU, inductor needs a C++ compiler. On CUDA, 'auto' stays off: the compiled path, and CUDA graphs (mode
'reduce-overhead') for the launch-bound acting step of issue 19, have not been measured on a GPU yet.
"""

from __future__ import annotations

import shutil

import torch

from emml.models.policy import EmmlModel


def cpp_compiler() -> str | None:
    """The C++ compiler inductor would use on a CPU, or None where there is none."""
    try:
        from torch._inductor.cpp_builder import get_cpp_compiler

        return get_cpp_compiler()
    except Exception:  # inductor raises its own InvalidCxxCompiler, or its private API moved
        return shutil.which("g++")


def check_compile(value: str, device: str) -> None:
    """Refuse, before any compute, a `compile` value (validated: one of `COMPILE`) that cannot run on ``device``
    (where training starts: emml/rl/hardware.py)."""
    if value == "on" and not device.startswith("cuda") and cpp_compiler() is None:
        raise ValueError(
            "compile='on': no C++ compiler found (g++), which torch.compile needs on a CPU; "
            "install one (apt-get install g++) or use compile='off' or 'auto'"
        )


def wants_compile(value: str, device: torch.device | str) -> bool:
    """Whether `compile` = ``value`` compiles on ``device``."""
    if value == "auto":
        return torch.device(device).type == "cpu" and cpp_compiler() is not None
    return value == "on"


def compile_model(model: EmmlModel) -> EmmlModel:
    """Compile ``model``'s conv stack and fusion unit in place; returns the model.

    Dynamo's cache first starts afresh (`torch.compiler.reset`): it is kept per function, not per model, and holds
    8 variants of one (`recompile_limit`); each run adds its own (acting on one thread, the update on two, the
    evaluations; each ablation's fusion switches). A campaign trains run after run in one process, and from its
    second run on the fusion hit that limit and ran uncompiled, said only in a warning (session 20). Compiled
    modules of earlier models stay correct after a reset: they compile again when next called."""
    torch.compiler.reset()
    for module in (model.image_encoder, model.fusion):
        module.compile()
    return model
