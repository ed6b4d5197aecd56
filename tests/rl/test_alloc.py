"""The allocator choice: glibc tuned in-process keeps freed large buffers (no page faults on reuse), EMML_MALLOC is
validated, and the run says which allocator ran."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from emml.cli import app
from emml.rl import alloc

# A child process, so that mallopt and LD_PRELOAD start from glibc's defaults: after a warm-up, 20 times allocate,
# fill and free a 64 MiB tensor (the size of a PPO minibatch's activations); count the loop's minor page faults.
CHILD = """
import json, resource, torch
from emml.rl import alloc
alloc.tune_glibc()
def faults():
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(10):
    torch.ones(64 << 20, dtype=torch.uint8)
before = faults()
for _ in range(20):
    torch.ones(64 << 20, dtype=torch.uint8)
print(json.dumps({"faults": faults() - before, "allocator": alloc.loaded()}))
"""


def _child(malloc: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "LD_PRELOAD"} | {"EMML_MALLOC": malloc}
    out = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def test_tuned_glibc_reuses_large_buffers_without_page_faults():
    plain, tuned = _child("glibc"), _child("glibc-tuned")
    assert plain["allocator"] == "glibc" and tuned["allocator"] == "glibc-tuned"
    pages = 20 * (64 << 20) // 4096
    assert plain["faults"] > pages // 2  # glibc maps and unmaps each buffer: every page faults again
    assert tuned["faults"] < pages // 100  # kept in the heap: reused without faults


TRAIN_CHILD = """
import hashlib, torch
from emml.rl import alloc
alloc.tune_glibc()
from emml.models import build_model
torch.manual_seed(0)
model = build_model("dual_attention", 20, 60, 108, 30)
opt = torch.optim.Adam(model.parameters(), lr=1e-3)
obs = {"image": torch.randint(0, 256, (4, 8, 3, 60, 108), dtype=torch.uint8), "tokens": torch.randint(1, 20, (4, 8, 6)),
       "task": torch.randint(0, 2, (4, 8)), "time": torch.randint(0, 30, (4, 8))}
for _ in range(3):
    out = model(obs, model.initial_state(8), torch.zeros(4, 8, dtype=torch.bool))[0]
    loss = out.logits.logsumexp(-1).mean() + out.value.pow(2).mean() + out.answer_logits.logsumexp(-1).mean()
    opt.zero_grad(); loss.backward(); opt.step()
params = b"".join(p.detach().numpy().tobytes() for p in model.parameters())
print(alloc.loaded(), hashlib.sha256(params).hexdigest())
"""


def test_the_allocator_changes_no_number():
    runs = []
    for malloc in ("glibc", "glibc-tuned"):
        env = {k: v for k, v in os.environ.items() if k != "LD_PRELOAD"} | {"EMML_MALLOC": malloc}
        out = subprocess.run([sys.executable, "-c", TRAIN_CHILD], env=env, capture_output=True, text=True, check=True)
        runs.append(out.stdout.split())
    assert [r[0] for r in runs] == ["glibc", "glibc-tuned"]
    assert runs[0][1] == runs[1][1]  # the same parameters, bit for bit, after three Adam steps


def test_bad_choice_names_the_variable_and_the_values(monkeypatch):
    monkeypatch.setenv("EMML_MALLOC", "jemalloc")
    with pytest.raises(ValueError, match=r"EMML_MALLOC='jemalloc'.*auto, tcmalloc, glibc-tuned, glibc"):
        alloc.choice()
    result = CliRunner().invoke(app, ["train", "--profile", "smoke", "--frames", "64"])
    assert result.exit_code == 2 and "EMML_MALLOC" in result.output


def test_forced_tcmalloc_refuses_when_absent(monkeypatch):
    monkeypatch.setenv("EMML_MALLOC", "tcmalloc")
    monkeypatch.setenv("LD_PRELOAD", "")
    monkeypatch.setattr(alloc, "TCMALLOC_PATHS", ("/nonexistent/libtcmalloc.so",))
    with pytest.raises(ValueError, match="EMML_MALLOC=tcmalloc: not installed"):
        alloc.reexec_under_tcmalloc()
