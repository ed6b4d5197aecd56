"""The bf16 option: refused (by name, before compute) on a CPU without native bf16, untouched fp32, and a bf16 run
whose convolutions really run in bf16 while the rest and PPO's losses stay fp32."""

from __future__ import annotations

import math

import pytest
import torch
from typer.testing import CliRunner

from emml.cli import app
from emml.config.profiles import profile_config
from emml.models import build_model
from emml.rl import precision
from emml.rl.hardware import check_runnable
from emml.rl.trainer import Trainer
from emml.runs.mirror import read_mirror
from emml.runs.naming import run_name
from emml.runs.results import read_results
from emml.runs.rundir import METRICS, results_csv
from tests.conftest import SMOKE


@pytest.fixture
def no_native_bf16(monkeypatch):
    monkeypatch.setattr(precision, "cpu_flags", lambda: {"fpu", "avx2", "fma"})


@pytest.fixture
def native_bf16(monkeypatch):
    monkeypatch.setattr(precision, "cpu_flags", lambda: {"avx2", "avx512f", "avx512_bf16"})


def test_bf16_is_refused_on_a_cpu_without_native_bf16(no_native_bf16, tmp_path):
    cfg = profile_config("smoke", "easy", {"precision": "bf16"})
    with pytest.raises(ValueError, match=r"precision='bf16'.*no native bf16.*avx512_bf16, amx_bf16.*precision='fp32'"):
        check_runnable(cfg.validate())  # the value is valid; the machine is asked where training starts
    result = CliRunner().invoke(
        app, ["train", "--profile", "smoke", "--set", 'precision="bf16"', "--set", f'run_root="{tmp_path}"']
    )
    assert result.exit_code == 2 and "no native bf16" in result.output
    assert not any(tmp_path.iterdir())  # refused before anything was written


def test_unknown_precision_names_the_allowed_values():
    with pytest.raises(ValueError, match=r"precision='fp16' is not allowed; choose one of 'fp32', 'bf16'"):
        profile_config("smoke", "easy", {"precision": "fp16"}).validate()


def _model_and_batch():
    torch.manual_seed(0)
    h, w = SMOKE["height"], SMOKE["width"]
    model = build_model("dual_attention", 20, h, w, 30)
    obs = {
        "image": torch.randint(0, 256, (1, 4, 3, h, w), dtype=torch.uint8),
        "tokens": torch.randint(1, 20, (1, 4, 6)),
        "task": torch.tensor([[0, 1, 0, 1]]),
        "time": torch.tensor([[0, 3, 5, 7]]),
    }
    return model, obs, model.initial_state(4), torch.ones(1, 4, dtype=torch.bool)


def test_fp32_runs_exactly_as_without_the_option():
    model, obs, state, start = _model_and_batch()
    plain = model(obs, state, start)[0]
    with precision.conv_precision(model, "fp32"):
        wrapped = model(obs, state, start)[0]
    for key, value in vars(plain).items():
        if torch.is_tensor(value):
            assert torch.equal(value, getattr(wrapped, key)), key


def test_bf16_runs_only_the_convolutions_in_bf16_and_restores_fp32_after(native_bf16, monkeypatch):
    """Inside conv_precision('bf16') the convolutions run in bf16 and nothing else does (the Linear layers and the
    outputs PPO reads stay fp32); outside it, evaluation's fp32 again, exactly."""
    model, obs, state, start = _model_and_batch()
    dtypes = {"conv": [], "linear": []}
    conv2d = torch.nn.functional.conv2d

    def spy(x, weight, *args):
        dtypes["conv"].append((x.dtype, weight.dtype))
        return conv2d(x, weight, *args)

    monkeypatch.setattr(torch.nn.functional, "conv2d", spy)
    for module in model.modules():
        if isinstance(module, torch.nn.Linear):
            module.register_forward_hook(lambda m, i, o: dtypes["linear"].append(o.dtype))
    plain = model(obs, state, start)[0]
    for d in dtypes.values():
        d.clear()
    with precision.conv_precision(model, "bf16"):
        out = model(obs, state, start)[0]
    assert len(dtypes["conv"]) == 3 and set(dtypes["conv"]) == {(torch.bfloat16, torch.bfloat16)}
    assert dtypes["linear"] and set(dtypes["linear"]) == {torch.float32}
    for key, value in vars(out).items():
        if torch.is_tensor(value) and value.is_floating_point():
            assert value.dtype == torch.float32, key
    assert torch.allclose(out.logits, plain.logits, atol=0.1)  # bf16 keeps ~3 significant digits
    assert not torch.equal(out.logits, plain.logits)
    assert torch.equal(model(obs, state, start)[0].logits, plain.logits)  # restored: fp32 after the block


def test_bf16_reaches_the_conv_stack_of_packed_runs(native_bf16):
    from emml.rl.packed import StackedModels

    models = [_model_and_batch()[0] for _ in range(2)]
    stacked = StackedModels(models)
    _, obs, state, start = _model_and_batch()
    obs = {k: v.repeat_interleave(2, dim=1) for k, v in obs.items()}
    state = {k: v.repeat_interleave(2, dim=0) for k, v in stacked.initial_state(4).items()}
    start = start.repeat_interleave(2, dim=1)
    plain = stacked(obs, state, start)[0]
    with precision.conv_precision(stacked, "bf16"):
        out = stacked(obs, state, start)[0]
    assert precision.image_encoders(stacked) and out.logits.dtype == torch.float32
    assert torch.allclose(out.logits, plain.logits, atol=0.1) and not torch.equal(out.logits, plain.logits)


def test_a_bf16_run_trains_with_finite_losses(native_bf16, tracking, no_leftovers):
    roots = {"run_root": tracking["run_root"], "results_root": tracking["results_root"], "table": "test"}
    cfg = profile_config("smoke", "easy", {**roots, "precision": "bf16", "frames": 64, "eval_episodes": 1})
    result = Trainer(cfg, quiet=True).train()
    assert result.frames >= 64
    losses = [v for _, key, v in read_mirror(result.run_dir / METRICS) if key.startswith("losses/")]
    assert losses and all(math.isfinite(v) for v in losses)
    row = read_results(results_csv(cfg)).set_index("run_name").loc[run_name(cfg)]
    assert row["precision"] == "bf16" and run_name(cfg).endswith("-bf16-s0-smoke")


def test_bf16_scales_pixels_straight_to_the_fp32_quotient_rounded_to_bf16():
    from emml.models.encoders import ImageEncoder

    enc = ImageEncoder(vocab_size=3)
    pixels = torch.arange(256, dtype=torch.uint8)
    enc.bf16 = True
    assert torch.equal(enc._scaled(pixels), (pixels.float() / 255).to(torch.bfloat16))
    enc.bf16 = False
    assert torch.equal(enc._scaled(pixels), pixels.float() / 255)
