"""`emml bench`: the figures come out, finite and in one run, for the smoke config (not a speed test)."""

import math

from emml.bench import bench_train
from emml.profiles import profile_config


def test_bench_train_reports_both_throughputs_and_the_split(tmp_path, tracking, no_leftovers):
    cfg = profile_config("smoke", "easy", model="dual_attention", aux=True)
    r = bench_train(cfg, updates=2)
    assert r["model_only_fps"] > 0 and r["end_to_end_fps"] > 0
    assert math.isclose(r["ratio"], r["end_to_end_fps"] / r["model_only_fps"], rel_tol=0.01)
    assert set(r["time_split"]) == {"simulate", "infer", "learn"}
    assert math.isclose(sum(r["time_split"].values()), 1.0, abs_tol=0.01)
