import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from emml.config import DoomConfig
from emml.envs.doom import DoomEnv
from emml.envs.vector import make_vector_env
from tests.conftest import SMOKE, engine_pids


def test_vector_env_matches_plain_env_and_autoresets(no_leftovers):
    cfg = DoomConfig(tasks="sgn", aux_labels=True, **SMOKE)
    plain = DoomEnv(cfg)
    try:
        with make_vector_env(cfg, 2) as venv:
            obs, info = venv.reset(seed=[11, 12])
            ref, ref_info = plain.reset(seed=11)
            assert obs["image"].dtype == np.uint8
            assert np.array_equal(obs["image"][0], ref["image"]) and np.array_equal(obs["aux"][0], ref["aux"])
            assert info["text"][0] == ref_info["text"]
            ended = 0
            for _ in range(60):
                obs, r, term, trunc, info = venv.step(np.array([[0, 0], [0, 0]]))
                ref, rr, rterm, rtrunc, _ = plain.step(np.array([0, 0]))
                if not rterm and not rtrunc:
                    assert np.array_equal(obs["image"][0], ref["image"]) and r[0] == pytest.approx(rr)
                if term.any() or trunc.any():
                    ended += 1
                    assert "final_info" in info
                    assert (obs["time"][term | trunc] == 0).all()  # same-step autoreset: next episode's first obs
                if rterm or rtrunc:
                    break
            assert ended >= 1
    finally:
        plain.close()


SCRIPT = textwrap.dedent(
    """
    import sys, time, numpy as np
    from emml.config import DoomConfig
    from emml.envs.engine import install_signal_handlers
    from emml.envs.vector import make_vector_env
    install_signal_handlers()
    cfg = DoomConfig(height=60, width=108)
    with make_vector_env(cfg, 2) as venv:
        venv.reset(seed=0)
        if sys.argv[1] == "raise":
            raise RuntimeError("boom")
        print("ready", flush=True)
        while True:
            venv.step(np.array([[1, 0], [2, 0]]))
            time.sleep(0.01)
    """
)


@pytest.mark.parametrize("how", ["sigterm", "sigint", "sigkill", "raise"])
def test_worker_parent_ending_leaves_no_engine(how, no_leftovers, tmp_path):
    """The parent of the workers ends by SIGTERM, Ctrl-C, SIGKILL or an exception: no engine or shm file stays."""
    import os
    import signal

    before = engine_pids()
    proc = subprocess.Popen(
        [sys.executable, "-c", SCRIPT, "raise" if how == "raise" else "run"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=os.getcwd(),
        start_new_session=True,
    )
    try:
        if how != "raise":
            assert proc.stdout.readline().strip() == "ready"
            assert len(engine_pids() - before) == 2
            sig = {"sigterm": signal.SIGTERM, "sigint": signal.SIGINT, "sigkill": signal.SIGKILL}[how]
            if how == "sigint":
                os.killpg(proc.pid, sig)  # Ctrl-C reaches the whole foreground process group
            else:
                os.kill(proc.pid, sig)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    deadline = time.monotonic() + 20
    while engine_pids() - before and time.monotonic() < deadline:
        time.sleep(0.05)
    assert engine_pids() - before == set()


def test_a_dead_worker_is_reported_not_waited_on(no_leftovers):
    from emml.envs.engine import WorkerDied

    with make_vector_env(DoomConfig(**SMOKE), 2) as venv:
        venv.reset(seed=0)
        os.kill(venv.processes[0].pid, signal.SIGKILL)  # its engine lives on and holds the pipe open
        t0 = time.monotonic()
        with pytest.raises(WorkerDied, match="env worker 0 .* died"):
            venv.step(np.array([[0, 0], [0, 0]]))
        assert time.monotonic() - t0 < 5
        venv.abort()  # ends the orphaned engine too (no_leftovers checks)
