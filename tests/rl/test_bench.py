"""`emml bench`: the figures come out, finite and in one run, for the smoke config (not a speed test)."""

import math
import os

from emml.config.profiles import profile_config
from emml.rl import alloc, bench
from emml.rl.bench import bench_train


def assert_ratio(r: dict, ratio: str, num: str, den: str) -> None:
    """r[ratio] is r[num] / r[den]: of the measured rates, which are printed to 0.1 frames/s, so that at a few
    frames/s (tests beside a training) the printed ones' ratio may differ by more than 1%."""
    printed = r[num] / r[den]
    assert abs(r[ratio] - printed) <= 0.05 * (1 + printed) / r[den] + 1e-3 + 0.01 * printed, (ratio, r[ratio], printed)


def test_bench_train_reports_both_throughputs_and_the_split(tmp_path, tracking, no_leftovers):
    cfg = profile_config("smoke", "easy", model="dual_attention", aux=True)
    r = bench_train(cfg, updates=2)
    assert r["model_only_fps"] > 0 and r["end_to_end_fps"] > 0
    assert r["allocator"] == alloc.loaded()
    assert math.isclose(r["model_only_fps"], sum(r["model_only_before_after"]) / 2, rel_tol=0.01)
    assert_ratio(r, "ratio", "end_to_end_fps", "model_only_fps")
    assert set(r["time_split"]) == {"simulate", "infer", "learn"}
    assert math.isclose(sum(r["time_split"].values()), 1.0, abs_tol=0.01)
    assert r["env_groups"] == 2 and r["lockstep_fps"] > 0  # double buffering is compared with lockstep
    assert_ratio(r, "double_buffer_gain", "end_to_end_fps", "lockstep_fps")


def test_the_time_split_is_over_the_updates_given():
    first = {"perf/simulate_s": 1.0, "perf/infer_s": 20.0, "perf/learn_s": 30.0}  # a warm-up that compiles
    later = {"perf/simulate_s": 1.0, "perf/infer_s": 1.0, "perf/learn_s": 2.0}
    assert bench.time_split([later, later]) == {"simulate": 0.25, "infer": 0.25, "learn": 0.5}
    assert bench.time_split([first, later])["infer"] == round(21 / 55, 3)


def test_bench_train_packs_runs_and_measures_the_simulator_limit(tmp_path, tracking, no_leftovers):
    cfg = profile_config("smoke", "easy", model="dual_attention", aux=False)
    r = bench_train(cfg, updates=1, runs=2, limit_steps=300)
    packed = r["packed"]
    assert packed["runs"] == 2 and len(packed["per_run_fps"]) == 2 and all(f > 0 for f in packed["per_run_fps"])
    assert math.isclose(packed["aggregate_fps"], sum(packed["per_run_fps"]), rel_tol=0.01)
    assert packed["simulator_limit_fps"] > packed["aggregate_fps"]  # raw engines outrun any training
    assert packed["threads_per_run"] == max(1, (os.cpu_count() or 1) // 2)


def test_bench_train_stacks_runs_in_one_model(tracking, no_leftovers):
    cfg = profile_config("smoke", "easy", model="dual_attention", aux=True)
    r = bench_train(cfg, updates=1, stack=2)
    assert r["stack"] == 2 and r["model_only_fps"] > 0 and r["stacked_model_only_fps"] > 0
    assert r["end_to_end_fps"] > 0 and r["stacked_end_to_end_fps"] > 0
    assert_ratio(r, "stacked_model_only_gain", "stacked_model_only_fps", "model_only_fps")
    assert_ratio(r, "stacked_end_to_end_gain", "stacked_end_to_end_fps", "end_to_end_fps")


def test_bench_alloc_runs_each_allocator_in_its_own_process(monkeypatch):
    envs = {"glibc-tuned": {"EMML_MALLOC": "glibc-tuned"}, "glibc": {"EMML_MALLOC": "glibc"}}
    monkeypatch.setattr(bench, "allocator_envs", lambda: envs)
    r = bench.bench_alloc(["--profile", "smoke", "--updates", "1"], rounds=1, parts=("model",))
    assert set(r["fps"]) == set(envs) and all(len(v["model"]) == 1 for v in r["fps"].values())
    assert max(v["model"] for v in r["ratio_to_best"].values()) == 1.0  # the child checked it ran on its allocator


def test_bench_workers_compares_envs_per_worker_end_to_end(no_leftovers):
    r = bench.bench_workers(["--profile", "smoke", "--updates", "1", "--set", "num_envs=4"], [1, 2], rounds=1)
    assert set(r["median_fps"]) == {"1 per worker", "2 per worker"}
    assert all(v["e2e"] > 0 for v in r["median_fps"].values())


def test_bench_env_measures_the_doom_room_and_the_house(no_leftovers):
    from emml.config.schema import DoomConfig, HouseConfig

    for cfg, name in ((DoomConfig(height=60, width=108), "doom"), (HouseConfig(height=60, width=108), "house")):
        result = bench.bench_env(cfg, steps=100, vector_steps=100)
        assert result["env"] == name
        figures = [
            result[k][m] for k in ("labels_off", "labels_on") for m in result[k] if isinstance(result[k][m], float)
        ]
        figures += [result[f"vector_{w}_workers_steps_per_s"] for w in (1, 2)]
        assert len(figures) == 12 and all(math.isfinite(x) and x > 0 for x in figures)
