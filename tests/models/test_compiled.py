"""`TrainConfig.compile` (emml/models/compiled.py): the compiled model is the plain model, within float tolerance."""

from __future__ import annotations

import copy

import pytest
import torch

from emml.config.schema import TrainConfig
from emml.models import build_model
from emml.models import compiled as compiled_module
from emml.models.compiled import compile_model, wants_compile
from emml.rl.hardware import check_runnable

V, H, W, L, STEPS = 12, 60, 108, 6, 20


def _obs(t: int, b: int, gen: torch.Generator) -> dict:
    return {
        "image": torch.randint(0, 256, (t, b, 3, H, W), dtype=torch.uint8, generator=gen),
        "tokens": torch.randint(1, V + 1, (t, b, L), generator=gen),
        "task": torch.randint(0, 2, (t, b), generator=gen),
        "time": torch.randint(0, STEPS, (t, b), generator=gen),
    }


def test_compiled_model_equals_the_plain_one_in_acting_and_in_the_update():
    torch.manual_seed(0)
    plain = build_model("dual_attention", V, H, W, STEPS)
    compiled = compile_model(copy.deepcopy(plain))
    assert list(compiled.state_dict()) == list(plain.state_dict())  # checkpoints keep their names
    gen = torch.Generator().manual_seed(1)
    with torch.no_grad():  # acting: one step of a small batch
        obs = _obs(1, 2, gen)
        starts = torch.ones(1, 2, dtype=torch.bool)
        a, _ = plain(obs, plain.initial_state(2), starts)
        b, _ = compiled(obs, compiled.initial_state(2), starts)
        torch.testing.assert_close(b.logits, a.logits, rtol=1e-4, atol=1e-5)
    obs = _obs(4, 2, gen)  # the update: a sequence, with gradients
    starts = torch.zeros(4, 2, dtype=torch.bool)
    outs = []
    for model in (plain, compiled):
        out, _ = model(obs, model.initial_state(2), starts)
        (out.logits.sum() + out.value.sum() + out.aux_logits.sigmoid().mean()).backward()
        outs.append(out)
    torch.testing.assert_close(outs[1].aux_logits, outs[0].aux_logits, rtol=1e-4, atol=1e-5)
    for (name, p), q in zip(plain.named_parameters(), compiled.parameters()):
        torch.testing.assert_close(q.grad, p.grad, rtol=1e-3, atol=1e-5, msg=name)


def test_compile_names_its_values_and_refuses_a_cpu_without_a_compiler(monkeypatch):
    with pytest.raises(ValueError, match="compile='yes' is not allowed; choose one of 'off', 'on', 'auto'"):
        TrainConfig(compile="yes").validate()
    monkeypatch.setattr(compiled_module, "cpp_compiler", lambda: None)
    cfg = TrainConfig(compile="on").validate()  # the value is valid: the machine is asked where training starts
    with pytest.raises(ValueError, match="no C\\+\\+ compiler"):
        check_runnable(cfg)
    assert not wants_compile("auto", "cpu")  # auto falls back to the plain model
    check_runnable(TrainConfig(compile="auto").validate())


def test_auto_compiles_on_a_cpu_with_a_compiler_only(monkeypatch):
    monkeypatch.setattr(compiled_module, "cpp_compiler", lambda: "g++")
    assert wants_compile("auto", "cpu") and wants_compile("on", "cpu") and not wants_compile("off", "cpu")
    assert not wants_compile("auto", "cuda")  # not measured on a GPU yet


def test_each_model_compiles_though_earlier_ones_filled_the_cache():
    """A campaign trains run after run in one process: dynamo's per-function cache (its recompile_limit) must not
    leave a later run's fusion uncompiled because earlier runs filled it."""
    from torch._dynamo.utils import counters

    threads = torch.get_num_threads()
    gen = torch.Generator().manual_seed(0)
    try:
        with torch._dynamo.config.patch(recompile_limit=2):  # dynamo's own patcher: monkeypatch's undo hides the key
            for name in ("dual_attention", "da_no_ga1", "da_no_ga2"):  # each ablation: other guards on the fusion
                model = compile_model(build_model(name, V, H, W, STEPS))
                before = counters["stats"]["unique_graphs"]
                with torch.no_grad():
                    for n in (1, 2):  # acting and update use different thread counts: one variant each
                        torch.set_num_threads(n)
                        x_image = model.image_encoder(_obs(1, 2, gen)["image"][0])
                        model.fusion(x_image, torch.rand(2, V), torch.rand(2, V))
                assert counters["stats"]["unique_graphs"] >= before + 2, name  # its fusion compiled, both variants
    finally:
        torch.set_num_threads(threads)
