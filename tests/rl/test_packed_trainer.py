"""Seeds trained packed in one process (emml/rl/packed_trainer.py): each run ends as its plain run would be written,
and its checkpoint is an ordinary one."""

from __future__ import annotations

import json
import os

import pandas as pd
import pytest

from emml.rl.packed_trainer import check_packable, train_packed
from emml.rl.trainer import train
from emml.runs.checkpoint import load_checkpoint
from emml.runs.rundir import CHECKPOINT, RESULTS
from emml.runs.store import metric_history
from tests.rl.test_trainer import smoke


def test_two_seeds_train_packed_each_into_its_own_run(tracking, no_leftovers):
    cfgs = [smoke(tracking, seed=s, aux=True, frames=128, eval_episodes=1) for s in (0, 1)]
    results = train_packed(cfgs, quiet=True)
    assert [r.frames for r in results] == [128, 128]
    assert len({r.run_id for r in results}) == 2 and len({r.run_dir for r in results}) == 2
    rows = pd.read_csv(os.path.join(tracking["results_root"], "test", "smoke.csv"))
    assert sorted(rows["seed"]) == [0, 1] and set(rows["frames"]) == {128}
    for cfg, r in zip(cfgs, results):
        assert json.loads((r.run_dir / RESULTS).read_text())["seed"] == cfg.seed
        saved = load_checkpoint(r.run_dir / CHECKPOINT)
        assert saved["finished"] and saved["update"] == 2 and saved["config"]["seed"] == cfg.seed
        assert [s for s, _ in metric_history(r.run_id, "charts/update")] == [64, 128]
        assert metric_history(r.run_id, "losses/aux")  # each run logs its own losses
    # a packed run's checkpoint is an ordinary one: the plain trainer extends one seed alone
    longer = train(smoke(tracking, seed=1, aux=True, frames=192, eval_episodes=1), quiet=True)
    assert longer.resumed and longer.run_id == results[1].run_id and longer.frames == 192
    # and the pack skips a finished run, training the other one alone
    again = train_packed([smoke(tracking, seed=s, aux=True, frames=192, eval_episodes=1) for s in (0, 1)], quiet=True)
    assert not again[0].skipped and again[0].frames == 192 and again[1].skipped


def test_runs_that_differ_in_more_than_seed_are_refused_by_name(tracking):
    with pytest.raises(ValueError, match="differ only in seed; these differ: aux"):
        check_packable([smoke(tracking, seed=0, aux=True), smoke(tracking, seed=1, aux=False)])
    with pytest.raises(ValueError, match="distinct seeds"):
        check_packable([smoke(tracking, seed=0), smoke(tracking, seed=0)])
    with pytest.raises(ValueError, match="minibatches=1"):
        check_packable([smoke(tracking, seed=s, **{"ppo.minibatches": 2}) for s in (0, 1)])


def test_a_pack_refuses_runs_at_different_updates(tracking, no_leftovers):
    train(smoke(tracking, seed=0, frames=64, eval_episodes=1), quiet=True)
    with pytest.raises(ValueError, match="same update"):
        train_packed([smoke(tracking, seed=s, frames=128, eval_episodes=1) for s in (0, 1)], quiet=True)


def test_a_pack_failing_as_it_opens_ends_every_started_run_failed(tracking, monkeypatch, no_leftovers):
    """The second run's first checkpoint fails after the first run's MLflow run started: both end FAILED, neither
    stays RUNNING (no engine has started yet)."""
    import mlflow

    from emml.rl import trainer

    written, real = [], trainer.save_checkpoint

    def second_fails(path, payload):
        written.append(path)
        if len(written) == 2:
            raise RuntimeError("the second run's folder went away")
        return real(path, payload)

    monkeypatch.setattr(trainer, "save_checkpoint", second_fails)
    with pytest.raises(RuntimeError, match="went away"):
        train_packed([smoke(tracking, seed=s, frames=128, eval_episodes=1) for s in (0, 1)], quiet=True)
    runs = mlflow.search_runs(experiment_names=["test"], output_format="list")
    assert sorted(r.info.status for r in runs) == ["FAILED", "FAILED"]


def test_packed_runs_hear_the_frames_trained_through_the_module_their_forward_calls():
    """`PackedLearner.at_frames`: the stacked runs' forward calls one template module (`StackedModels`), so the
    schedule of `answer_gate_frames` (issue 48) is told to it, for every run at once."""
    from emml.models import build_model
    from emml.rl.packed import StackedModels
    from emml.rl.packed_trainer import PackedLearner

    runs = [build_model("dual_attention", 22, 36, 36, 30, answer_gate_frames=100) for _ in range(2)]
    from emml.config.schema import TrainConfig

    learner = PackedLearner(StackedModels(runs), None, TrainConfig())
    assert learner.model.template[0].fusion.warming
    learner.at_frames(100)
    assert not learner.model.template[0].fusion.warming
