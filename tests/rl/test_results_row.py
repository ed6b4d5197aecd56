"""A results row says what was trained (issue 85): its frames are the frames the run trained (whole updates: a
150-frame target trains 3 updates of 64, 192 frames), its eval_episodes the final evaluation's and its seed the run's,
for a run stopped short and resumed, and for a finished run extended to a larger target. Every other test trains a
whole number of updates, where the row's frames and the config's target agree: the mutant "row frames from the
config's target" passed 221 tests."""

from __future__ import annotations

import signal
import threading
from pathlib import Path

import pandas as pd
import pytest

from emml.config.profiles import profile_config
from emml.rl.trainer import train
from emml.runs.checkpoint import load_checkpoint
from emml.runs.rundir import CHECKPOINT, RESULTS, read_results, run_name


def _to_main_thread(sig) -> None:
    """The signal to this process's main thread, delivered before the call returns (`os.kill` to the process may
    reach another thread first, and the main thread see it bytecodes later on a busy machine)."""
    signal.pthread_kill(threading.main_thread().ident, sig)


def _smoke(tracking, **over):
    roots = {"run_root": tracking["run_root"], "results_root": tracking["results_root"]}
    over = {"eval_every": 0, "eval_episodes": 3, "final_eval_episodes": 1, "diagnose_episodes": 0, **over}
    return profile_config("smoke", "easy", {**roots, "table": "test", **over}, seed=3)


def _row(tracking, cfg) -> pd.Series:
    rows = pd.read_csv(Path(tracking["results_root"]) / "test" / "smoke.csv")
    (row,) = [r for _, r in rows.iterrows() if r["run_name"] == run_name(cfg)]
    return row


def test_a_run_stopped_short_then_resumed_records_the_frames_it_trained_not_its_target(
    tracking, monkeypatch, no_leftovers
):
    import emml.rl.trainer as trainer_module
    from emml.envs.stops import install_signal_handlers

    cfg = _smoke(tracking, frames=150, checkpoint_every=100)  # 3 updates of 2 actors x 32 steps: 192 frames
    assert cfg.num_updates * cfg.frames_per_update == 192 != cfg.frames
    real_update, calls = trainer_module.ppo_update, {"n": 0}

    def term_on_second(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            _to_main_thread(signal.SIGTERM)  # held until the update's block ends: the run stops at 128 frames
        return real_update(*args, **kwargs)

    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    install_signal_handlers()
    monkeypatch.setattr(trainer_module, "ppo_update", term_on_second)
    try:
        with pytest.raises(SystemExit):
            train(cfg, quiet=True)
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)
    monkeypatch.setattr(trainer_module, "ppo_update", real_update)
    directory = Path(tracking["run_root"]) / "test" / run_name(cfg)
    assert load_checkpoint(directory / CHECKPOINT)["frames"] == 128  # stopped short: no row yet
    assert not (Path(tracking["results_root"]) / "test" / "smoke.csv").exists()
    result = train(_smoke(tracking, frames=150), quiet=True)
    assert result.resumed and result.frames == 192
    row = _row(tracking, cfg)
    assert row["frames"] == 192  # not the target, 150
    assert row["eval_episodes"] == 1 and row["seed"] == 3  # the final evaluation's episodes (not eval_episodes, 3)
    assert read_results(directory / RESULTS)["frames"] == 192


def test_a_finished_run_extended_records_the_new_frames_and_the_new_final_evaluation(tracking, no_leftovers):
    first = train(_smoke(tracking, frames=128), quiet=True)
    assert first.frames == 128 and _row(tracking, _smoke(tracking))["frames"] == 128
    cfg = _smoke(tracking, frames=200, final_eval_episodes=2)  # a larger target: 4 updates, 256 frames
    extended = train(cfg, quiet=True)
    assert extended.resumed and extended.run_id == first.run_id and extended.frames == 256
    row = _row(tracking, cfg)
    assert row["frames"] == 256  # not the target, 200, nor the first finish, 128
    assert row["eval_episodes"] == 2 and row["seed"] == 3
    assert len(pd.read_csv(Path(tracking["results_root"]) / "test" / "smoke.csv")) == 1  # the row, upserted
