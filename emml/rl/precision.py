"""Reduced-precision training, opt-in: bf16 autocast for the conv stack, acting and the PPO update.

Weights, optimizer state and the losses stay fp32; only the autocast-eligible ops (convolutions, matmuls) run in
bf16. On CPU this pays only where the CPU has native bf16 arithmetic (AVX-512 BF16 or AMX on x86, the bf16
extension on Arm): elsewhere oneDNN emulates it and runs several times slower than fp32 (notes/cpu-training.md),
so the option refuses there instead. On CUDA it is the usual mixed precision (bf16 needs no loss scaling).
The paper trains in fp32; the `paper` profile keeps fp32.
"""

from __future__ import annotations

import contextlib

import torch

PRECISIONS = ("fp32", "bf16")
"""Values of TrainConfig.precision."""

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
    """Refuse, before any compute, a precision the device cannot run fast: names the field and the allowed values."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision={precision!r}: allowed values are {', '.join(PRECISIONS)}")
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


def autocast(precision: str, device: torch.device | str):
    """The context the model's forward passes run in: bf16 autocast, or nothing for fp32."""
    if precision != "bf16":
        return contextlib.nullcontext()
    return torch.autocast(torch.device(device).type, dtype=torch.bfloat16)


def fp32_outputs(out) -> dict:
    """A ModelOutput's fields as a dict, floating tensors cast to fp32: PPO's losses are computed in fp32."""
    return {k: v.float() if torch.is_tensor(v) and v.is_floating_point() else v for k, v in vars(out).items()}
