"""Reduced-precision training, opt-in: the conv stack's convolutions in bf16, in acting and in the PPO update.

Only the convolutions run in bf16. Weights, optimizer state, the conv stack's logits, the rest of the model (the
small per-step matmuls and GRU cells of the recurrent policy) and the losses stay fp32: autocast over the whole
model measured slower, its per-op casts costing more than bf16 saves on small ops (docs/throughput.md).

On CPU bf16 pays only where the CPU has native bf16 arithmetic (AVX-512 BF16 or AMX on x86, the bf16 extension on
Arm): elsewhere oneDNN emulates it, several times slower than fp32 (notes/cpu-training.md), so the option refuses
there instead. On CUDA it needs no loss scaling. The paper trains in fp32; the `paper` profile keeps fp32.
"""

from __future__ import annotations

import contextlib

import torch
from torch import nn

NATIVE_BF16_FLAGS = ("avx512_bf16", "amx_bf16", "bf16")
"""CPU flags (/proc/cpuinfo) that mean native bf16 arithmetic: x86 AVX-512 BF16, AMX, Arm BF16."""


def _cpuinfo(*keys: str) -> str | None:
    """The first value of /proc/cpuinfo under one of ``keys``; None where absent or unreadable."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key.strip() in keys:
                    return value.strip()
    except OSError:
        pass
    return None


def cpu_flags() -> set[str]:
    """The CPU's feature flags (x86 'flags', Arm 'Features'); empty where /proc/cpuinfo is unreadable."""
    return set((_cpuinfo("flags", "Features") or "").split())


def cpu_model() -> str:
    return _cpuinfo("model name") or "this CPU"


def check_precision(precision: str, device: str) -> None:
    """Refuse, before any compute, a precision (validated: one of `PRECISIONS`) the device cannot run fast, naming
    the field and what to use instead (where training starts: emml/rl/hardware.py)."""
    if precision == "fp32":
        return
    if device.startswith("cuda"):
        if torch.cuda.is_available() and not torch.cuda.is_bf16_supported():
            raise ValueError("precision='bf16': this GPU has no bf16 support; use precision='fp32'")
        return
    native = cpu_flags() & set(NATIVE_BF16_FLAGS)
    if not native:
        raise ValueError(
            f"precision='bf16': {cpu_model()} has no native bf16 arithmetic (none of the CPU flags "
            f"{', '.join(NATIVE_BF16_FLAGS)}), where bf16 runs slower than fp32; use precision='fp32'"
        )


def image_encoders(model: nn.Module) -> list[nn.Module]:
    """The conv stacks (`ImageEncoder`s) of a model, or of the template a `StackedModels` runs its stack through."""
    from emml.models.encoders import ImageEncoder

    roots = [model, *getattr(model, "template", [])]
    return [m for root in roots for m in root.modules() if isinstance(m, ImageEncoder)]


@contextlib.contextmanager
def conv_precision(model: nn.Module, precision: str):
    """Within it, ``model``'s conv stack runs in ``precision`` (bf16: its convolutions in bf16, logits back in
    fp32); as before, after it. Acting and the PPO update run inside it; evaluation runs outside, in fp32."""
    encoders = image_encoders(model)
    before = [e.bf16 for e in encoders]
    for e in encoders:
        e.bf16 = precision == "bf16"
    try:
        yield
    finally:
        for e, b in zip(encoders, before):
            e.bf16 = b
