"""Which malloc the learner runs on, and making the fast one the default without a system package.

PyTorch on CPU allocates and frees large activation and gradient buffers on every PPO step. glibc serves blocks
above its mmap threshold with fresh mappings and gives them back on free, so every step pays page faults: training
runs at about half the speed it reaches under tcmalloc (`docs/throughput.md`, "allocators"). glibc can be told to keep
that memory: with mmap disabled and trimming put out of reach, freed buffers stay in the heap and are reused. That is
``mallopt`` in this process, so it needs no package and no re-exec, and it applies inside pytest too.

Order of preference: tcmalloc when the system has it (the CLI re-execs under it), else glibc tuned in-process.
``EMML_MALLOC=glibc`` keeps glibc's defaults (for measuring); the run's ``allocator`` tag says what ran.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

TCMALLOC_PATHS = (
    "/usr/lib/x86_64-linux-gnu/libtcmalloc_minimal.so.4",
    "/usr/lib/x86_64-linux-gnu/libtcmalloc.so.4",
    "/usr/lib/aarch64-linux-gnu/libtcmalloc_minimal.so.4",
)
CHOICES = ("auto", "tcmalloc", "glibc-tuned", "glibc")
"""Values of EMML_MALLOC: auto (tcmalloc when installed, else glibc-tuned), or one of them forced."""

# <malloc.h> parameter numbers for mallopt(3)
M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_MAX = -1, -2, -4
TOP_PAD = 64 << 20
"""Extra heap grown on each brk, so a step's first large tensors do not each extend the heap."""
_tuned = False


def choice() -> str:
    """EMML_MALLOC, validated."""
    value = os.environ.get("EMML_MALLOC", "auto").strip() or "auto"
    if value not in CHOICES:
        raise ValueError(f"EMML_MALLOC={value!r}: allowed values are {', '.join(CHOICES)}")
    return value


def tcmalloc_path() -> str | None:
    return next((p for p in TCMALLOC_PATHS if os.path.exists(p)), None)


def loaded() -> str:
    """The allocator this process runs on: tcmalloc, jemalloc, mimalloc (preloaded), glibc-tuned or glibc."""
    try:
        with open("/proc/self/maps") as f:
            maps = f.read()
    except OSError:
        return "unknown"
    for name in ("tcmalloc", "jemalloc", "mimalloc"):
        if name in maps:
            return name
    return "glibc-tuned" if _tuned else "glibc"


def tune_glibc() -> bool:
    """Keep freed memory in glibc's heap (no mmap for large blocks, no trimming): ~1.6-1.8x CPU training speed
    here. Idempotent; a no-op (False) under another allocator, off glibc, or with EMML_MALLOC=glibc."""
    global _tuned
    if _tuned:
        return True
    if choice() == "glibc" or loaded() != "glibc" or not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # musl and others have no mallopt
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    ok = mallopt(M_MMAP_MAX, 0) and mallopt(M_TRIM_THRESHOLD, 2**31 - 1) and mallopt(M_TOP_PAD, TOP_PAD)
    _tuned = bool(ok)
    return _tuned


def reexec_under_tcmalloc(module: str = "emml.cli") -> None:
    """Re-exec this command once under tcmalloc when it is installed, wanted and not loaded yet; otherwise tune
    glibc in-process. Worker processes inherit LD_PRELOAD."""
    want = choice()
    if want in ("auto", "tcmalloc") and "tcmalloc" not in os.environ.get("LD_PRELOAD", ""):
        lib = tcmalloc_path()
        if lib is not None:
            env = {**os.environ, "LD_PRELOAD": f"{lib} {os.environ.get('LD_PRELOAD', '')}".strip()}
            os.execve(sys.executable, [sys.executable, "-m", module, *sys.argv[1:]], env)
        if want == "tcmalloc":
            raise ValueError(f"EMML_MALLOC=tcmalloc: not installed (looked in {', '.join(TCMALLOC_PATHS)})")
    tune_glibc()
