"""One training loop for plain and packed runs (issue 35): the same parameters, bit for bit, as the two loops
before it, and every run of a pack gets what a plain run gets (stop checkpoint, perf metrics)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
import torch

from emml.config.profiles import profile_config
from emml.rl.packed_trainer import train_packed
from emml.rl.trainer import env_seeds, train
from emml.runs.rundir import CHECKPOINT, METRICS

REFERENCE = json.loads((Path(__file__).parent / "data" / "smoke_parameters.json").read_text())


def _digest(state: dict) -> str:
    h = hashlib.sha256()
    for key in sorted(state):
        h.update(key.encode())
        h.update(state[key].detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


def _cfg(tracking, seed: int, table: str):
    cfg = profile_config("smoke", "easy", {"table": table}, aux=True, seed=seed, run_root=tracking["run_root"],
                         results_root=tracking["results_root"])  # fmt: skip
    cfg.frames, cfg.num_envs, cfg.num_steps, cfg.threads = 1024, 4, 64, 1
    cfg.eval_episodes = cfg.final_eval_episodes = 1
    return cfg


def _same_machine() -> bool:
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")), "")
    return (torch.__version__, cpu, torch.backends.cpu.get_cpu_capability()) == (
        REFERENCE["torch"], REFERENCE["cpu"], REFERENCE["cpu_capability"])  # fmt: skip


def test_the_env_seed_formula_interleaves_packed_runs_as_plain_runs_seed_them():
    plain = {s: env_seeds([s], 3, 4) for s in (0, 1)}
    assert plain[0] == [12, 13, 14, 15] and plain[1] == [1012, 1013, 1014, 1015]  # seed·1000 + update·B + actor
    assert env_seeds([0, 1], 3, 4) == [x for pair in zip(plain[0], plain[1]) for x in pair]  # actor b·N + r


def test_a_smoke_training_gives_the_parameters_of_the_loops_before_it(tracking, no_leftovers):
    """Plain and packed runs through the one loop end with the parameters the two loops gave before issue 35,
    bit for bit, where torch and the CPU are those the reference was measured on (float results differ between
    CPU kinds); elsewhere the run must still train and save both runs."""
    plain = train(_cfg(tracking, 0, "plain"), quiet=True)
    packed = train_packed([_cfg(tracking, 0, "packed"), _cfg(tracking, 1, "packed")], quiet=True)
    got = {"plain_s0": plain.run_dir} | {f"packed_s{s}": r.run_dir for s, r in zip((0, 1), packed)}
    digests = {k: _digest(torch.load(d / CHECKPOINT, weights_only=False)["model"]) for k, d in got.items()}
    assert len(set(digests.values())) == 3
    for run in got.values():  # every packed run logs what a plain run logs
        keys = {line.split(",")[1] for line in (run / METRICS).read_text().splitlines()[1:]}
        assert {"perf/simulate_s", "perf/learn_s", "charts/fps", "eval/sgn_train"} <= keys
    if not _same_machine():
        pytest.skip("the reference parameters were measured with another torch or CPU: " + REFERENCE["about"])
    assert digests == {k: REFERENCE[k] for k in digests}
