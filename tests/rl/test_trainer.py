"""The trainer end to end at the smoke profile: every model, resume after a kill, reproducible evaluation, bad
configs, and a learning test that PPO + answer CE + aux BCE beat chance."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from emml.config.profiles import profile_config
from emml.config.schema import TrainConfig
from emml.eval.evaluate import evaluate_checkpoint
from emml.models import MODELS
from emml.rl.trainer import train
from emml.runs.checkpoint import load_checkpoint, save_checkpoint
from emml.runs.mirror import read_mirror
from emml.runs.results import read_results
from emml.runs.rundir import (
    CHECKPOINT,
    METRICS,
    RESULTS,
    ConfigMismatch,
    check_resumable,
    results_csv,
    run_dir,
    run_name,
)
from emml.runs.store import metric_history


def smoke(tracking, **over) -> TrainConfig:
    fields = {k: over.pop(k) for k in ("model", "aux", "seed") if k in over}
    roots = {"run_root": tracking["run_root"], "results_root": tracking["results_root"]}
    return profile_config("smoke", "easy", {**roots, "table": "test", **over}, **fields)


@pytest.mark.parametrize("model", sorted(MODELS))
def test_every_model_trains_a_few_hundred_frames(model, tracking, no_leftovers):
    cfg = smoke(tracking, model=model, aux=model != "text_only", frames=128, eval_episodes=2)
    result = train(cfg, quiet=True)
    assert result.frames == 128
    assert set(result.metrics) == {"sgn_train", "sgn_test", "eqa_train", "eqa_test"}
    assert all(0.0 <= v <= 1.0 for v in result.metrics.values())
    saved = json.loads((result.run_dir / RESULTS).read_text())
    assert saved["frames"] == 128 and saved["profile"] == "smoke" and saved["git_sha"]
    trained = load_checkpoint(result.run_dir / CHECKPOINT)["config"]  # what reports read the deviations from:
    assert saved["config"] == json.loads(json.dumps(trained)) and trained["env"]["height"] == cfg.env.height
    import pandas as pd

    rows = pd.read_csv(os.path.join(tracking["results_root"], "test", "smoke.csv"))
    assert rows["run_name"].tolist() == [run_name(cfg)] and "config" not in rows
    assert rows.loc[0, "frames"] == 128 and rows.loc[0, "seed"] == 0 and rows.loc[0, "model"] == model
    losses = metric_history(result.run_id, "losses/answer")
    assert len(losses) == 2  # one point per update (2 updates of 2 x 32 frames)


def test_each_update_logs_where_its_time_went(tracking, no_leftovers):
    result = train(smoke(tracking, frames=192, eval_every=0), quiet=True)
    fps = [v for _, v in metric_history(result.run_id, "charts/fps")]
    parts = [[v for _, v in metric_history(result.run_id, f"perf/{p}_s")] for p in ("simulate", "infer", "learn")]
    assert len(fps) == 3 and all(len(p) == 3 for p in parts)  # one point per update, not cumulative:
    for u, f in enumerate(fps):  # the update's own seconds add up to its wall time (64 frames / its frames/s)
        spent = sum(p[u] for p in parts)
        assert 0.75 * 64 / f <= spent <= 64 / f * (1 + 1e-9), (u, spent, 64 / f)  # slack: loop code, preemption


def test_the_target_mask_control_trains_and_scores_on_the_referents_cells(tracking, no_leftovers):
    """The referent's cells are privileged (the env gives them in info): the trainer and the evaluation ask the env
    for them in the observation for the one model that reads them, the 'target_mask' control."""
    cfg = smoke(
        tracking, aux=True, frames=64, eval_episodes=1, final_eval_episodes=1, model_options={"control": "target_mask"}
    )
    assert not cfg.env.target_in_obs  # the run's config is unchanged: asked for where the envs are made
    result = train(cfg, quiet=True)
    assert result.frames == 64 and set(result.metrics) >= {"sgn_train", "eqa_train"}


def test_a_log_line_splits_the_time_since_the_previous_line(tracking, monkeypatch, no_leftovers):
    import emml.rl.trainer as trainer

    lines = []
    real = trainer.log_line
    monkeypatch.setattr(trainer, "log_line", lambda *a, **k: lines.append(dict(a[-1])) or real(*a, **k))
    result = train(smoke(tracking, frames=192, eval_every=0, log_every=1), quiet=False)
    logged = {p: [v for _, v in metric_history(result.run_id, f"perf/{p}_s")] for p in ("simulate", "infer", "learn")}
    assert len(lines) == 3  # one line per update: each splits that update's seconds, not all since the start
    for u, line in enumerate(lines):
        assert line == pytest.approx({p: v[u] for p, v in logged.items()})


def test_a_run_dir_moved_to_another_store_resumes_with_its_whole_curve(tracking, tmp_path, monkeypatch, no_leftovers):
    first = train(smoke(tracking, frames=128, eval_episodes=1), quiet=True)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path}/other.db")  # a fresh clone, another machine
    with pytest.warns(UserWarning, match=f"MLflow run {first.run_id} is not in this store"):
        longer = train(smoke(tracking, frames=256, eval_episodes=1), quiet=True)
    assert longer.resumed and longer.run_id != first.run_id and longer.frames == 256
    assert [s for s, _ in metric_history(longer.run_id, "charts/update")] == [64, 128, 192, 256]
    assert [s for s, _ in metric_history(longer.run_id, "eval/sgn_train")] == [128, 256]
    assert load_checkpoint(longer.run_dir / CHECKPOINT)["run_id"] == longer.run_id


def test_finished_run_is_not_retrained_but_can_be_extended(tracking, no_leftovers):
    cfg = smoke(tracking, frames=64, eval_episodes=1)
    first = train(cfg, quiet=True)
    again = train(smoke(tracking, frames=64, eval_episodes=1), quiet=True)
    assert again.skipped and again.run_id == first.run_id and again.metrics == first.metrics
    longer = train(smoke(tracking, frames=192, eval_episodes=1), quiet=True)
    assert not longer.skipped and longer.resumed and longer.run_id == first.run_id and longer.frames == 192
    assert [s for s, _ in metric_history(first.run_id, "charts/update")] == [64, 128, 192]


def test_the_model_hears_the_frames_trained_before_each_rollout_and_on_resume(tracking, no_leftovers, monkeypatch):
    """`train_loop` tells the model the frames trained before each rollout (`EmmlModel.at_frames`), resumed runs
    from where they stopped: what `answer_gate_frames` (issue 48's warm-up) switches on."""
    from emml.models.fusion import DualAttention

    heard = []
    monkeypatch.setattr(DualAttention, "at_frames", lambda self, frames: heard.append(frames))
    over = {"model_options.answer_gate_frames": 128}
    train(smoke(tracking, frames=128, eval_episodes=1, **over), quiet=True)
    train(smoke(tracking, frames=192, eval_episodes=1, **over), quiet=True)
    assert heard == [0, 64, 128]


def _train_and_sigkill(tracking, ready, frames: int = 2048) -> tuple[TrainConfig, dict, int]:
    """`emml train` (smoke, 2,048 frames, a checkpoint every 2 updates) in a subprocess, SIGKILLed as soon as
    ``ready(checkpoint, logged_steps)`` holds (``logged_steps()`` reads MLflow); returns the config, the
    checkpoint it left and the killed pid."""
    args = [
        sys.executable,
        "-m",
        "emml.cli",
        "train",
        "--profile",
        "smoke",
        "--table",
        "test",
        "--frames",
        str(frames),
        "--set",
        f'run_root="{tracking["run_root"]}"',
        "--set",
        "checkpoint_every=2",
        "--set",
        "eval_episodes=1",
        "--quiet",
    ]
    env = {**os.environ, "EMML_MALLOC": "glibc-tuned"}
    proc = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    cfg = smoke(tracking, frames=frames, checkpoint_every=2, eval_episodes=1)
    path = run_dir(cfg) / CHECKPOINT
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if path.exists():
                ckpt = load_checkpoint(path)
                if ready(ckpt, lambda c=ckpt: [s for s, _ in metric_history(c["run_id"], "charts/update")]):
                    break
            time.sleep(0.05)
        else:
            pytest.fail("the run never reached the state to kill it in")
        os.kill(proc.pid, signal.SIGKILL)  # no cleanup in the parent: its workers must end their engines alone
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    return cfg, load_checkpoint(path), proc.pid


def _one_run_one_value_per_step(cfg, killed, pid, sampler_started: bool = True) -> None:
    import tempfile

    import mlflow

    leftover = Path(tempfile.gettempdir()) / f"emml-mp-{os.getuid()}" / str(pid)
    assert any(leftover.glob("pymp-*")) or not sampler_started, "the killed learner's multiprocessing dir"
    result = train(cfg, quiet=True)
    assert not leftover.exists()  # swept by the next learner
    frames = cfg.frames
    assert result.resumed and result.run_id == killed["run_id"] and result.frames == frames
    done = load_checkpoint(run_dir(cfg) / CHECKPOINT)
    assert done["finished"] and done["update"] == frames // 64 and done["frames"] == frames
    for key in ("charts/update", "losses/policy", "train/success_sgn"):
        steps = [s for s, _ in metric_history(result.run_id, key)]
        assert len(steps) == len(set(steps)), (key, steps)  # one value per step, even for the redone updates
    assert [s for s, _ in metric_history(result.run_id, "charts/update")] == list(range(64, frames + 1, 64))
    mirror = read_mirror(run_dir(cfg) / METRICS)  # the run dir's own copy of the curves: the same points
    assert len({(k, st) for st, k, _ in mirror}) == len(mirror)
    assert [st for st, k, _ in mirror if k == "charts/update"] == list(range(64, frames + 1, 64))
    runs = mlflow.search_runs(experiment_names=["test"], output_format="list")
    assert [(r.info.run_id, r.info.status) for r in runs] == [(result.run_id, "FINISHED")]  # none left RUNNING


def test_resume_after_sigkill_between_checkpoints_logs_each_step_once(tracking, no_leftovers):
    # killed after it logged an update that its last checkpoint does not hold: the resumed run redoes that update
    cfg, killed, pid = _train_and_sigkill(tracking, lambda c, steps: c["update"] >= 4 and max(steps()) > c["frames"])
    assert not killed["finished"] and 4 <= killed["update"] < 32
    _one_run_one_value_per_step(cfg, killed, pid)


def test_a_run_killed_before_its_first_update_is_resumed_not_duplicated(tracking, no_leftovers):
    cfg, killed, pid = _train_and_sigkill(tracking, lambda c, steps: True, frames=256)  # the first checkpoint
    assert killed["update"] == 0  # the checkpoint written at start: before it, a rerun made a second MLflow run
    _one_run_one_value_per_step(cfg, killed, pid, sampler_started=False)


def test_a_failing_run_is_marked_failed(tracking, monkeypatch, no_leftovers):
    import mlflow

    from emml.rl import trainer

    def broken(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(trainer, "ppo_update", broken)
    with pytest.raises(RuntimeError, match="boom"):
        train(smoke(tracking, frames=64), quiet=True)
    (run,) = mlflow.search_runs(experiment_names=["test"], output_format="list")
    assert run.info.status == "FAILED"


def test_eval_of_a_checkpoint_reproduces_its_numbers(tracking, no_leftovers):
    cfg = smoke(tracking, frames=128, final_eval_episodes=3, seed=3)
    result = train(cfg, quiet=True)
    again = evaluate_checkpoint(result.run_dir / CHECKPOINT, episodes=3, seed=10_000)
    assert again == result.metrics
    assert evaluate_checkpoint(result.run_dir / CHECKPOINT, episodes=3, seed=10_000) == again


@pytest.mark.parametrize(
    "over, field",
    [
        ({"model": "transformer"}, "transformer"),
        ({"env.difficulty": "medium"}, "difficulty"),
        ({"ppo.lr": -1.0}, "lr"),
        ({"answer_supervision": "never"}, "answer_supervision"),
        ({"frames": 0}, "frames"),
        ({"env.height": 20}, "height"),
        ({"env.label_grid": "odd"}, "label_grid"),
        ({"model_options": {"control": "detectors"}}, "control"),  # a control reads the aux labels: needs aux
        ({"model_options": {"control": "oracle"}}, "control"),
        ({"envs_per_worker": 3}, "envs_per_worker=3 must be a positive divisor"),
        ({"seed": -1}, r"seed=-1 must be >= 0"),
        ({"table": "../x"}, r"table='../x' must be a plain name"),
        ({"table": ""}, r"table='' must be a plain name"),
        ({"frames": 63}, r"frames=63 is less than one update \(num_envs × num_steps = 64\); the minimum is 64"),
        ({"cuda_graphs": True, "ppo.minibatches": 2}, r"cuda_graphs=true .* needs ppo.minibatches=1, got 2"),
        ({"cuda_graphs": "yes"}, r"'cuda_graphs': expected true or false, got 'yes'"),
    ],
)
def test_bad_config_fails_before_any_compute(over, field, tracking, no_leftovers):
    model = over.pop("model", "dual_attention")
    with pytest.raises(ValueError, match=field):
        train(smoke(tracking, model=model, **over), quiet=True)
    assert not os.path.exists(tracking["run_root"]) and not os.path.exists(tracking["results_root"])


def test_every_evaluation_logs_the_diagnostics(tracking, no_leftovers):
    """diag/* beside eval/* at each evaluation: attention and AP for Dual-Attention, AP alone for a baseline."""
    for model, has_attention in (("dual_attention", True), ("ga", False)):
        cfg = smoke(tracking, model=model, aux=True, frames=128, eval_every=64, eval_episodes=1, seed=5)
        cfg.diagnose_episodes = 2
        run_id = train(cfg, quiet=True).run_id
        for key in ("detector_ap", "actor_sensitivity"):
            assert [s for s, _ in metric_history(run_id, f"diag/{key}")] == [64, 128]
        assert bool(metric_history(run_id, "diag/attention_on_target")) == has_attention
        assert bool(metric_history(run_id, "diag/gate_on_attribute")) == has_attention  # GA2: issue 82


def test_a_house_run_trains_evaluates_diagnoses_and_reloads(tracking, no_leftovers):
    """Table 5's runs go through the same trainer: the House's env in the workers, the evaluation and the
    diagnostics (its spawn is fixed, so the actor's sensitivity is defined as in Easy), and a checkpoint that reloads
    with its HouseConfig."""
    from emml.config.schema import HouseConfig
    from emml.runs.rundir import load_model

    cfg = smoke(tracking, frames=128, eval_episodes=2, seed=2, **{"env.difficulty": "house", "eval_every": 128})
    cfg.diagnose_episodes = 1
    result = train(cfg, quiet=True)
    assert run_name(cfg) == "dual_attention-house-noaux-s2-smoke"
    assert set(result.metrics) == {"sgn_train", "sgn_test", "eqa_train", "eqa_test"}
    assert [s for s, _ in metric_history(result.run_id, "diag/actor_sensitivity")] == [128]
    _, saved = load_model(result.run_dir / CHECKPOINT)
    assert isinstance(saved.env, HouseConfig) and saved.env.max_steps == 420


def test_unknown_override_is_named():
    with pytest.raises(ValueError, match="nosuch"):
        profile_config("smoke", "easy", {"nosuch": 1})
    with pytest.raises(ValueError, match="profile='huge'"):
        profile_config("huge")


def test_an_lr_sweep_trains_one_run_per_value_and_resume_refuses_another_identity(tracking, no_leftovers):
    """ppo.lr identifies a run (issue 35): each value gets its own run dir; a checkpoint whose identity differs
    under the same name (here its words) is refused by field, before anything is touched."""
    import torch

    runs = [train(smoke(tracking, frames=64, eval_episodes=1, **{"ppo.lr": lr}), quiet=True) for lr in (1e-3, 2e-3)]
    assert len({r.run_dir for r in runs}) == 2 and all(r.run_dir.name.endswith(f"+ppo.lr={lr:g}") for r, lr in
                                                       zip(runs, (1e-3, 2e-3)))  # fmt: skip
    cfg = smoke(tracking, frames=64, eval_episodes=1, **{"ppo.lr": 1e-3})
    saved = torch.load(runs[0].run_dir / CHECKPOINT, weights_only=False)["config"]
    with pytest.raises(ConfigMismatch, match="env.vocabulary"):
        check_resumable({**saved, "env": {**saved["env"], "vocabulary": ["only", "words"]}}, cfg, Path("c.pt"))


def test_a_field_added_after_a_checkpoint_reads_as_its_default(tracking):
    current = smoke(tracking).to_dict()
    older = {k: v for k, v in current.items() if k != "precision"}  # written before the field existed
    check_resumable(older, smoke(tracking), Path("checkpoint.pt"))
    with pytest.raises(ConfigMismatch, match="precision"):
        check_resumable(older, smoke(tracking, precision="bf16"), Path("checkpoint.pt"))


def test_how_a_run_runs_is_not_its_identity(tracking):
    """Device, threads, workers, roots, cadences and the frame target may change between a run and its resume."""
    saved = smoke(tracking).to_dict()
    runtime = {"threads": 1, "env_groups": 1, "frames": 4096, "eval_every": 64, "checkpoint_every": 2}
    other = smoke(tracking, **runtime)
    check_resumable(saved, other, Path("checkpoint.pt"))
    assert run_name(other) == run_name(smoke(tracking))


def test_the_score_plays_final_eval_episodes_and_the_curve_eval_episodes(tracking, monkeypatch, no_leftovers):
    """results.json and the results row hold the final evaluation over `final_eval_episodes` per (task, split), with
    their count and seed; the curve's evaluations play `eval_episodes` (issue 33: 100 episodes are too noisy)."""
    import emml.rl.trainer as trainer

    played, real = [], trainer.evaluate
    monkeypatch.setattr(
        trainer, "evaluate", lambda m, env, n, **k: played.append((n, k["seed"])) or real(m, env, n, **k)
    )
    cfg = smoke(tracking, frames=128, eval_every=64, eval_episodes=1, final_eval_episodes=2)
    result = train(cfg, quiet=True)
    assert played == [(1, 10_000), (2, 10_000)]  # at 64 frames (the curve), then the score at 128
    saved = json.loads((result.run_dir / RESULTS).read_text())
    row = read_results(results_csv(cfg)).iloc[0]
    assert (saved["eval_episodes"], saved["eval_seed"]) == (row["eval_episodes"], row["eval_seed"]) == (2, 10_000)


def test_a_measurement_run_is_trained_and_checkpointed_but_not_scored(tracking, monkeypatch, no_leftovers):
    """``score=False`` (`emml bench train`'s temporary runs): no final evaluation, no results.json, no results row;
    the checkpoint is finished."""
    import emml.rl.trainer as trainer

    played = []
    monkeypatch.setattr(trainer, "evaluate", lambda *a, **k: played.append(a) or {})
    result = train(smoke(tracking, frames=128, score=False), quiet=True)
    assert played == [] and result.metrics == {} and result.frames == 128
    assert not (result.run_dir / RESULTS).exists() and not results_csv(smoke(tracking)).exists()
    assert load_checkpoint(result.run_dir / CHECKPOINT)["finished"]


def test_a_checkpoint_from_before_final_eval_episodes_resumes_and_finishes(tracking, no_leftovers):
    """Evaluation size is not part of a run's identity: a checkpoint written before the field existed resumes, under
    another eval_episodes too, and its score plays the new count."""
    first = train(smoke(tracking, frames=64, eval_episodes=1, final_eval_episodes=1), quiet=True)
    path = first.run_dir / CHECKPOINT
    old = load_checkpoint(path)
    config = {k: v for k, v in old["config"].items() if k != "final_eval_episodes"}
    save_checkpoint(path, {**old, "config": config, "finished": False})
    longer = train(smoke(tracking, frames=128, eval_episodes=2, final_eval_episodes=2), quiet=True)
    assert longer.resumed and longer.run_id == first.run_id and longer.frames == 128
    assert json.loads((longer.run_dir / RESULTS).read_text())["eval_episodes"] == 2
    assert load_checkpoint(path)["finished"]


LEARNING_QUESTIONS = ["what color is the pillar", "what color is the tall pillar", "what color is the short pillar"]


def test_learning_beats_chance(tracking, no_leftovers):
    """EQA on Easy about the pillars (answers red or green: chance 0.5), smoke resolution, with aux labels.
    PPO must learn to answer and the answer head to read the colour. Measured with this seed (0) at 16k frames
    (session 14, this config): greedy accuracy 0.925 at 40 episodes and training success 0.88 over the last 100
    episodes (seed 2: 0.975 and 0.85); its curve (session 13, evaluated every 8k frames) 0.95 / 0.925 / 0.975 / 0.95
    at 8k / 16k / 24k / 32k, so 16k frames, half the 32k trained until session 14 (CI time), lose nothing. We assert
    0.75, 3 sd above chance at 40 episodes, and 0.7. lr 1e-3 instead of the paper's 2.5e-4 so that it fits in CI's
    time. Seed-sensitive: with seed 1 the answer head learns too slowly and the policy settles at 0.40 (0.40 and 0.48
    at 16k frames; 0.40 even after 64k); training is deterministic under a seed on CPU, so this test is stable, but it
    pins one seed. Lockstep (env_groups=1) and double-buffered sampling (2, the default) gave the same accuracies for
    seeds 0, 1, 2: 0.90, 0.40, 0.95."""
    cfg = smoke(
        tracking,
        aux=True,
        frames=16384,
        num_envs=8,
        num_steps=32,
        final_eval_episodes=40,
        checkpoint_every=50,
        **{"env.tasks": "eqa", "env.instructions": tuple(LEARNING_QUESTIONS), "ppo.lr": 1e-3},
    )
    result = train(cfg, quiet=True)
    assert result.metrics["eqa_train"] >= 0.75, result.metrics
    assert metric_history(result.run_id, "train/success_eqa")[-1][1] >= 0.7


def demo_sgn(tracking, frames: int, seed: int, model_options: dict | None = None, **over) -> TrainConfig:
    """Easy SGN only at the demo scale (60×108, 4 actors × 64 steps), aux on, scored once at the end (40 greedy
    episodes, 20 diagnosed): the config of the SGN learning tests, with ``over`` as further dotted overrides."""
    fields = {
        "run_root": tracking["run_root"],
        "results_root": tracking["results_root"],
        "table": "test",
        "frames": frames,
        "eval_every": 0,
        "final_eval_episodes": 40,
        "diagnose_episodes": 20,
        "checkpoint_every": 1000,
        "env.tasks": "sgn",
        **over,
    }
    return profile_config("demo", "easy", fields, aux=True, seed=seed, model_options=model_options or {})


GROUNDED_INSTRUCTIONS = ("go to the green object", "go to the blue object", "go to the yellow object")
GROUNDED_FRAMES = 32_768
GROUNDED_THRESHOLD = 0.6
"""Measured through `train` with this config, evaluated every 8,192 frames (greedy SGN train, 40 episodes, at
24,576 / 32,768 / 40,960 frames): seed 0 (the test's) 0.23 / 1.00 / (not run), seed 1 0.23 / 0.97 / 0.95, seed 2
0.23 / 0.60 / 0.97; actor sensitivity at 40,960 frames 0.63 (seed 1) and 0.71 (seed 2). The test trains seed 0 to
32,768 frames (40,960 until session 13: CI time). Chance is 0.2 (one object of five; sd
0.063 at 40 episodes): 0.6 is 6 sd above it. With x_S as the paper writes it (entries ~1/(h·w): `state_scale=False`,
the code before issue 12) seed 0 ends at 0.23 with actor sensitivity 0.01 (chance at every evaluation): this test
fails there."""


def test_sgn_policy_acts_on_a_grounded_state(tracking, no_leftovers):
    """Instruction following on a small Easy SGN task: three colour instructions, the referent on any of the five
    slots, the paper's learning rate and losses, demo scale (60×108, 4 actors × 64 steps). The words are grounded
    by the perfect-detector control (x_I := the aux labels, `control = "detectors"`), so what is tested is the half
    of SGN that did not learn before issue 12: PPO and the policy module must act on the grounded state x_S. The
    greedy agent must beat chance clearly and its first move must depend on where the target stands. ~2.5 minutes
    on 2 cores.

    The learned detectors are the other half: `test_sgn_learning_beats_chance` (marked slow, ~8 minutes: the
    detectors need ~100k frames before the attention is sharp enough to act on; docs/fidelity.md, "Why SGN
    learns") and the EQA learning test, which reads the colour through the same conv3 channels."""
    cfg = demo_sgn(
        tracking,
        GROUNDED_FRAMES,
        seed=0,
        model_options={"control": "detectors"},
        **{"env.instructions": GROUNDED_INSTRUCTIONS},
    )
    result = train(cfg, quiet=True)
    assert result.metrics["sgn_train"] >= GROUNDED_THRESHOLD, result.metrics
    assert metric_history(result.run_id, "diag/actor_sensitivity")[-1][1] >= 0.2  # it turns towards the target


SGN_FRAMES = 122_880
SGN_SEED = 1
SGN_THRESHOLD = 0.4
"""Greedy SGN train accuracy at SGN_FRAMES with this config (40 episodes), measured through `emml train`: seed 0
0.50, seed 1 0.65 (the test's seed: the fastest of the three, to keep the test near 4 minutes), seed 2 0.30; at
163,840 frames 0.42, 0.85, 0.50. Chance is 0.2 (sd 0.063 at 40 episodes): 0.4 is 3 sd above it."""


@pytest.mark.slow
def test_sgn_learning_beats_chance(tracking, no_leftovers):
    """Instruction following (Easy SGN, all 42 training instructions) with the paper's model, its own learned word
    detectors, learning rate and losses, at the demo scale (60×108, 4 actors × 64 steps): the policy must act on
    the grounded state and beat chance (0.2: one object of five), and its first move must depend on where the
    target stands. About 8 minutes on 2 cores, so it is left out of `make test` (run it with `make test-slow`):
    the word detectors need ~100k frames before the attention lands on the target (docs/fidelity.md, "Why SGN
    learns").

    The same config on the code before issue 12 (3ace057) ends at greedy SGN train 0.175 (test 0.225): chance, and
    this test fails there."""
    cfg = demo_sgn(tracking, SGN_FRAMES, seed=SGN_SEED)
    result = train(cfg, quiet=True)
    assert result.metrics["sgn_train"] >= SGN_THRESHOLD, result.metrics
    assert metric_history(result.run_id, "diag/actor_sensitivity")[-1][1] >= 0.2  # it turns towards the target


def _params_after_512_frames(tracking, name: str, **over) -> dict:
    """The parameters a 512-frame smoke run (4 actors × 64 steps, aux) ends with, under the fields ``over``."""
    import torch

    cfg = smoke(tracking, aux=True, frames=512, num_envs=4, num_steps=64, eval_episodes=1, **over)
    cfg.table = name
    result = train(cfg, quiet=True)
    return torch.load(result.run_dir / "checkpoint.pt", weights_only=False)["model"]


def test_double_buffered_sampling_trains_exactly_like_lockstep(tracking, no_leftovers):
    """Double buffering changes when actors step, not what the learner sees: on CPU, under one seed, both loops
    take the same actions and end with the same parameters up to float rounding (the policy's matrix products
    run on batches of 2 instead of 4, which moves log-probs by ~1e-7). Measured on the quick profile too:
    identical success curves and final accuracies over 204,800 frames."""
    import torch

    params = {g: _params_after_512_frames(tracking, f"groups{g}", env_groups=g) for g in (1, 2)}
    assert params[1].keys() == params[2].keys()
    assert all(torch.allclose(params[1][k], params[2][k], rtol=0, atol=1e-5) for k in params[1])


def test_workers_hosting_several_envs_train_exactly_alike(tracking, no_leftovers):
    """envs_per_worker changes which process steps an env, not what it does: same parameters, bit for bit."""
    import torch

    params = {k: _params_after_512_frames(tracking, f"per_worker{k}", envs_per_worker=k) for k in (1, 2)}
    assert all(torch.equal(params[1][key], params[2][key]) for key in params[1])


def test_smoke_numbers_are_not_recorded_under_the_committed_results(tmp_path):
    from emml.config.paths import project_path
    from emml.runs.rundir import record_result

    cfg = profile_config("smoke", "easy", {"results_root": "results", "table": "test"})
    with pytest.raises(ValueError, match="the 'smoke' profile's numbers are not results"):
        record_result({"run_name": run_name(cfg), "metrics": {"sgn_test": 0.5}}, cfg)
    assert not (project_path("results") / "test").exists()
    assert profile_config("smoke").results_root == "scratch/results"  # where smoke numbers go by default


def test_a_run_stopped_during_an_evaluation_evaluates_there_when_resumed(tracking, monkeypatch, no_leftovers):
    """A stop (Ctrl-C / SIGTERM) inside the evaluation after an update keeps that update (its checkpoint is saved
    at the evaluation's frames); the resumed run plays the evaluation it missed before training on, so the curve
    has its point (before session 14 it went on to the next one: PACMAN's 900k point was lost so)."""
    from emml.rl.trainer import Trainer

    real_eval = Trainer.evaluate_at

    def stopped(self, model, frames, final=False):
        raise KeyboardInterrupt

    monkeypatch.setattr(Trainer, "evaluate_at", stopped)
    cfg = smoke(tracking, frames=256, checkpoint_every=100, eval_every=128, eval_episodes=1, final_eval_episodes=1)
    with pytest.raises(KeyboardInterrupt):
        train(cfg, quiet=True)
    assert load_checkpoint(run_dir(cfg) / CHECKPOINT)["frames"] == 128  # the update before the evaluation
    monkeypatch.setattr(Trainer, "evaluate_at", real_eval)
    result = train(cfg, quiet=True)
    assert result.resumed and result.frames == 256
    assert [s for s, _ in metric_history(result.run_id, "eval/sgn_train")] == [128, 256]


@pytest.mark.parametrize("where", ["collect", "update"])
def test_a_stopped_run_keeps_its_last_whole_update(tracking, monkeypatch, where, no_leftovers):
    """Ctrl-C / SIGTERM between checkpoints: stopped while collecting, the run saves the updates it finished (its
    model and optimizer are those of its last whole update); stopped inside an update, it keeps its last
    checkpoint. Either way the MLflow run ends KILLED and a rerun resumes it."""
    import mlflow

    import emml.rl.trainer as trainer_module
    from emml.rl.sampler import Sampler

    calls = {"n": 0}
    real_collect, real_update = Sampler.collect, trainer_module.ppo_update

    def stop_on_third(real):
        def wrapped(*args, **kwargs):
            calls["n"] += 1
            if calls["n"] == 3:
                raise KeyboardInterrupt
            return real(*args, **kwargs)

        return wrapped

    if where == "collect":
        monkeypatch.setattr(Sampler, "collect", stop_on_third(real_collect))
    else:
        monkeypatch.setattr(trainer_module, "ppo_update", stop_on_third(real_update))
    cfg = smoke(tracking, frames=512, checkpoint_every=100, eval_every=0)
    with pytest.raises(KeyboardInterrupt):
        train(cfg, quiet=True)
    saved = load_checkpoint(run_dir(cfg) / CHECKPOINT)
    assert (saved["update"], saved["frames"]) == ((2, 128) if where == "collect" else (0, 0))
    (run,) = mlflow.search_runs(experiment_names=["test"], output_format="list")
    assert run.info.status == "KILLED"
    monkeypatch.setattr(Sampler, "collect", real_collect)
    monkeypatch.setattr(trainer_module, "ppo_update", real_update)
    result = train(cfg, quiet=True)
    assert result.resumed and result.frames == 512
    steps = [s for s, _ in metric_history(result.run_id, "charts/update")]
    assert steps == list(range(64, 513, 64))  # one value per step


def test_eq1_over_the_content_words_trains_resumes_and_reloads_with_the_runs_words(tracking, no_leftovers):
    """`model_options.eq1_words = 'content'` (issue 34): the trainer sets Eq. 1's mask from the run's words, the
    checkpoint carries it, a resumed run and `load_model` read it back."""
    from emml.runs.rundir import load_model
    from emml.tasks.language import load_dataset

    over = {"model_options.eq1_words": "content", "eval_episodes": 1, "final_eval_episodes": 1}
    first = train(smoke(tracking, aux=True, frames=64, **over), quiet=True)
    assert "eq1content" in first.run_dir.name
    resumed = train(smoke(tracking, aux=True, frames=128, **over), quiet=True)
    assert resumed.run_dir == first.run_dir and resumed.frames == 128
    model, cfg = load_model(resumed.run_dir / CHECKPOINT)
    content = load_dataset(cfg.env.dataset).content_words()
    assert model.fusion.eq1_ready
    assert [bool(m) for m in model.fusion.eq1_mask.tolist()] == [w in content for w in cfg.env.vocabulary]


def test_a_sigterm_during_an_update_keeps_the_update_and_its_point_of_the_curve(tracking, monkeypatch, no_leftovers):
    """A SIGTERM that lands inside the PPO update stops the run after it (`stop_after`): the checkpoint holds that
    update and the metrics mirror its point, so a resumed run's curve misses no update (before session 16 the stop
    came between the update and its log line, and each stop lost one point)."""
    import signal

    import emml.rl.trainer as trainer_module
    from emml.envs.engine import install_signal_handlers

    real_update, calls = trainer_module.ppo_update, {"n": 0}

    def term_on_third(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 3:
            os.kill(os.getpid(), signal.SIGTERM)  # held until the update's block ends
        return real_update(*args, **kwargs)

    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGHUP)}
    install_signal_handlers()
    monkeypatch.setattr(trainer_module, "ppo_update", term_on_third)
    cfg = smoke(tracking, frames=512, checkpoint_every=100, eval_every=0)
    try:
        with pytest.raises(SystemExit) as stop:
            train(cfg, quiet=True)
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)
    assert stop.value.code == 128 + signal.SIGTERM
    assert load_checkpoint(run_dir(cfg) / CHECKPOINT)["frames"] == 192  # the third update, kept whole
    assert max(s for s, k, _ in read_mirror(run_dir(cfg) / METRICS) if k == "charts/update") == 192  # and its point


def test_a_torn_metrics_line_is_cut_back_on_resume_and_the_run_dir_still_imports(
    tracking, tmp_path, monkeypatch, capsys, no_leftovers
):
    """Issue 54: a kill in the middle of a write leaves metrics.csv ending in a torn line; the resumed run appended
    its first point onto it (both lost) and the run dir no longer imported. Now it is cut back first, with a note."""
    from emml.runs.import_runs import import_runs
    from emml.runs.records import read_points

    first = train(smoke(tracking, frames=128, eval_episodes=1), quiet=True)
    mirror = run_dir(smoke(tracking)) / METRICS
    with open(mirror, "a") as f:
        f.write("192,losses/pol")  # the next update's points, cut short by a kill
    capsys.readouterr()
    result = train(smoke(tracking, frames=256, eval_episodes=1), quiet=True)
    assert result.resumed and result.run_id == first.run_id and result.frames == 256
    assert f"note: {mirror}: line " in capsys.readouterr().err
    points = read_points(mirror)  # every line a point (RecordError names one that is not)
    assert len({(k, st) for st, k, _ in points}) == len(points)  # one value per step
    for key in ("charts/update", "losses/policy"):
        assert [st for st, k, _ in points if k == key] == [64, 128, 192, 256], key
    assert [s for s, _ in metric_history(result.run_id, "losses/policy")] == [64, 128, 192, 256]
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path}/elsewhere.db")  # another machine's store
    (imported,) = import_runs([run_dir(smoke(tracking))], log=None)
    assert imported.outcome == "imported", imported.reason
    assert [s for s, _ in metric_history(imported.mlflow_run_id, "losses/policy")] == [64, 128, 192, 256]


def test_a_garbage_metrics_line_or_results_json_fails_naming_file_and_line(tracking, no_leftovers):
    from emml.runs.records import RecordError

    train(smoke(tracking, frames=64, eval_episodes=1), quiet=True)
    mirror = run_dir(smoke(tracking)) / METRICS
    mirror.write_text(mirror.read_text().replace("\n", "\nnot a point\n", 1))
    with pytest.raises(RecordError, match=rf"^{mirror}: line 2: not a metric point"):
        train(smoke(tracking, frames=128, eval_episodes=1), quiet=True)
    results = run_dir(smoke(tracking)) / RESULTS  # issue 54: a garbage results.json crashed `emml train` naming none
    results.write_text('{"run_id": "x", ')
    with pytest.raises(ValueError, match=rf"^{results}: not JSON \(.*line 1 column"):
        train(smoke(tracking, frames=64, eval_episodes=1), quiet=True)
