"""Models of one's own (docs/own-model.md): a toy fusion written outside the package registers
through `--plugin`, `EMML_PLUGINS` or an entry point, appears in every list of models, and is trained, evaluated
and diagnosed through `emml train`, and as a row of its own table through `emml run`, in child processes too."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

import emml.models.plugins as plugins
from emml.cli import app
from emml.models import registry

runner = CliRunner()

TOY = '''"""A fusion of one's own, outside the package: x_S = gain · vec(x_I ⊙ x_BoW), answers from the channel means;
its options declared beside it."""

from dataclasses import dataclass

from torch import nn

from emml.models import Fusion, FusionOptions, FusionOutput, model_option, register_model, register_variant


@dataclass
class ToyOptions(FusionOptions):
    gain: float = model_option(1.0, name="gain{}")
    """x_S's scale; a run that sets it is named 'gain2'."""
    detach: bool = model_option(False)
    """Stop the answer's gradient into x_I (no name part: a run that sets it is named '+model_options.detach=True')."""

    def check(self):
        if not self.gain > 0:
            raise ValueError(f"ModelConfig.gain={self.gain!r} must be > 0")


@register_model("toy", "Toy: x_S = gain · vec(x_I ⊙ x_BoW)")
class Toy(Fusion):
    uses_bow = True
    options = ToyOptions

    def __init__(self, vocab_size, height, width, gain=1.0, detach=False):
        super().__init__()
        self.state_dim = vocab_size * height * width
        self.answer = nn.Linear(vocab_size, vocab_size)
        self.gain, self.detach = gain, detach

    @classmethod
    def from_config(cls, cfg, vocab_size, height, width):
        return cls(vocab_size, height, width, gain=cfg.options.gain, detach=cfg.options.detach)

    def forward(self, x_image, x_bow, x_sent):
        state = self.gain * (x_image * x_bow[:, :, None, None]).flatten(1)
        x = x_image.detach() if self.detach else x_image
        return FusionOutput(state=state, answer_logits=self.answer(x.mean(dim=(2, 3))))


register_variant("toy_no_indicator", "toy", "Toy w/o task indicator", task_indicator=False)
'''

SHORT = {"frames": 64, "eval_episodes": 1, "final_eval_episodes": 1, "diagnose_episodes": 0, "env.max_steps": 12}
"""A run of one update (smoke: 2 actors × 32 steps) and one episode per evaluation."""

TABLE = """title = "Toy beside the paper's models"
paper_label = "tab:toy"
status = "active"

[columns]
difficulties = ["easy"]
aux = [false]
metrics = {{ "SGN" = "sgn_test", "EQA" = "eqa_test" }}

[[rows]]
label = "Toy"
model = "toy"
overrides = {{ num_envs = 2, num_steps = 32, {short}, run_root = "{run_root}", results_root = "{results_root}" }}
"""


@pytest.fixture
def sandbox(monkeypatch):
    """The model registry and the plugin loader as they are, restored after the test; no EMML_PLUGINS."""
    monkeypatch.setattr(registry, "_ENTRIES", dict(registry._ENTRIES))
    monkeypatch.setattr(plugins, "_loaded", set())
    monkeypatch.setattr(plugins, "_entry_points_done", True)  # no installed distribution's plugins here
    monkeypatch.setenv(plugins.ENV_VAR, "")  # recorded, so that its value before the test comes back after it, also
    monkeypatch.delenv(plugins.ENV_VAR)  # when the CLI set it (`--plugin`)
    modules = set(sys.modules)
    yield
    for name in set(sys.modules) - modules:
        if name.startswith("emml_plugin_") or name.startswith("toy_"):
            del sys.modules[name]


def forget_plugins(monkeypatch) -> None:
    """A process that never loaded the plugin: the registry as emml declares it, nothing loaded."""
    monkeypatch.setattr(registry, "_ENTRIES", {k: v for k, v in registry._ENTRIES.items() if v.source == "emml"})
    monkeypatch.setattr(plugins, "_loaded", set())
    monkeypatch.delenv(plugins.ENV_VAR, raising=False)
    for name in [n for n in sys.modules if n.startswith("emml_plugin_")]:
        del sys.modules[name]


@pytest.fixture
def toy(tmp_path) -> Path:
    """The toy plugin, a file in a folder outside the package."""
    folder = tmp_path / "mine"
    folder.mkdir()
    path = folder / "toy_fusion.py"
    path.write_text(TOY)
    return path


def models_json(*plugin: str) -> dict[str, dict]:
    result = runner.invoke(app, [*plugin, "models", "--height", "60", "--width", "108", "--json"])
    assert result.exit_code == 0, result.output
    return {r["name"]: r for r in json.loads(result.stdout)}


def test_every_list_of_models_derives_from_the_registry(sandbox):
    from torch import nn

    from emml.config.schema import TrainConfig
    from emml.models import (
        ARCHITECTURES,
        MODELS,
        Fusion,
        FusionOutput,
        ModelConfig,
        build_model,
        check_architecture,
        model_config,
        register_model,
    )

    assert "probe" not in MODELS and "probe" not in models_json()
    with pytest.raises(ValueError, match="unknown fusion name='probe'"):
        check_architecture(ModelConfig(name="probe").validate())

    @register_model("probe", "Probe: x_S = vec(x_I)")
    class Probe(Fusion):
        def __init__(self, vocab_size, height, width):
            super().__init__()
            self.state_dim = vocab_size * height * width
            self.answer = nn.Linear(vocab_size, vocab_size)

        def forward(self, x_image, x_bow, x_sent):
            return FusionOutput(state=x_image.flatten(1), answer_logits=self.answer(x_image.mean(dim=(2, 3))))

    assert list(MODELS)[-1] == "probe" and "probe" in ARCHITECTURES
    assert check_architecture(ModelConfig(name="probe").validate()).name == "probe"
    assert model_config(TrainConfig(model="probe").validate().model).name == "probe"
    row = models_json()["probe"]
    assert row["description"] == "Probe: x_S = vec(x_I)" and row["source"] == __name__ and row["parameters"] > 0
    model = build_model("probe", 6, 60, 108, 20)
    assert isinstance(model.fusion, Probe) and model.window == 0
    assert not model.text_encoder.sentence  # it reads no x_sent: no sentence GRU
    with pytest.raises(ValueError, match="'ga1' is not an option of model 'probe'; its options: embed_dim"):
        model_config("probe", ga1=False)  # ablations are options of the fusion that reads them (Dual-Attention)
    with pytest.raises(ValueError, match="'probe' is already registered"):
        register_model("probe", "another", Fusion)
    with pytest.raises(TypeError, match="not a subclass of emml.models.Fusion"):
        register_model("plain", "a plain module", nn.Linear)


def test_a_plugin_loads_from_the_option_or_the_variable_once(sandbox, toy, monkeypatch):
    from emml.models import MODELS

    assert "toy" not in MODELS
    monkeypatch.setenv(plugins.ENV_VAR, str(toy))
    assert "toy" in MODELS and MODELS["toy_no_indicator"].switches == {"task_indicator": False}  # read: loaded
    assert MODELS["toy"].source == str(toy)
    module = sys.modules[MODELS["toy"].fusion.__module__]
    plugins.load_plugins()
    assert sys.modules[MODELS["toy"].fusion.__module__] is module  # once per process
    forget_plugins(monkeypatch)
    assert "toy" not in models_json()
    monkeypatch.chdir(toy.parent)  # the option takes a path relative to the working directory: absolute for children
    rows = models_json("--plugin", "toy_fusion.py")
    assert rows["toy"]["source"] == str(toy) and "toy_no_indicator" in rows
    assert rows["toy"]["options"] == {"gain": 1.0, "detach": False}  # its own, listed
    assert os.environ[plugins.ENV_VAR] == str(toy)  # for the processes the command starts


def test_an_installed_distribution_registers_through_its_entry_point(sandbox, tmp_path, monkeypatch):
    from emml.models import MODELS

    (tmp_path / "toy_ep_fusion.py").write_text(TOY.replace('"toy"', '"toy_ep"'))
    dist = tmp_path / "toy_ep-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-ep\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[emml.models]\ntoy_ep = toy_ep_fusion\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(plugins, "_entry_points_done", False)
    assert "toy_ep" in MODELS and MODELS["toy_ep"].source == "toy_ep_fusion"


@pytest.mark.parametrize(
    "plugin,why",
    [
        ("missing.py", "no such file or folder"),
        ("no_such_package.fusion", "no module named 'no_such_package'"),
        ("broken.py", "failed while importing: ZeroDivisionError: division by zero"),
        ("empty.py", "registered no model"),
        ("taken.py", "failed while importing: ValueError: model 'ga' is already registered (by emml)"),
    ],
)
def test_a_bad_plugin_is_named_in_one_line(sandbox, tmp_path, plugin, why):
    (tmp_path / "broken.py").write_text("1 / 0\n")
    (tmp_path / "empty.py").write_text("x = 1\n")
    (tmp_path / "taken.py").write_text(TOY.replace('"toy"', '"ga"'))
    spec = str(tmp_path / plugin) if plugin.endswith(".py") else plugin
    result = runner.invoke(app, ["--plugin", spec, "models"])
    assert result.exit_code == 2, result.output
    assert result.output.startswith(f"error: plugin {spec!r}") and why in result.output, result.output
    assert result.output.count("\n") == 1 and "Traceback" not in result.output


def test_a_plugin_declares_its_options_in_its_file(sandbox, toy, monkeypatch):
    """Issue 52 (4): the toy's options are its own: a run sets them as any model option, they are checked against
    its declaration (type, check()) naming the field before any compute, and the one declared with a name part
    spells it in the run name; the other is named as a swept field. Other models do not take them."""
    from emml.config.profiles import profile_config
    from emml.config.schema import TrainConfig, apply_overrides
    from emml.models import MODELS, model_config, model_options
    from emml.rl.hardware import check_runnable
    from emml.runs.naming import run_name

    monkeypatch.setenv(plugins.ENV_VAR, str(toy))
    assert model_options("toy")["gain"] == 1.0 and model_options("toy_no_indicator")["task_indicator"] is False
    assert model_config("toy", gain=2).gain == 2 and model_config("toy").options.detach is False

    def cfg(**options):
        return profile_config("smoke", "easy", {f"model_options.{k}": v for k, v in options.items()}, model="toy")

    assert run_name(cfg(gain=2)) == "toy-easy-noaux-gain2-s0-smoke"
    assert run_name(cfg(gain=0.5, sentence_readout="mean")) == "toy-easy-noaux-sentmean-gain0.5-s0-smoke"
    assert run_name(cfg(gain=1.0)) == run_name(cfg()) == "toy-easy-noaux-s0-smoke"  # the default: not spelled
    assert run_name(cfg(detach=True)) == "toy-easy-noaux-s0-smoke+model_options.detach=True"
    for options, message in [
        ({"gain": -1}, "ModelConfig.gain=-1 must be > 0"),
        ({"gain": "high"}, "ModelConfig.gain='high' must be a number"),
        ({"detach": 1}, "ModelConfig.detach=1 must be true or false"),
        ({"gian": 2}, "model_options: 'gian' is not an option of model 'toy'; its options: embed_dim, "),
    ]:
        with pytest.raises(ValueError, match=re.escape(message)):
            check_runnable(cfg(**options))
    with pytest.raises(ValueError, match="'gain' is not an option of model 'ga'"):
        check_runnable(apply_overrides(TrainConfig(model="ga"), {"model_options.gain": 2}).validate())
    assert "gain" not in model_options("dual_attention") and MODELS["toy"].fusion.options.__name__ == "ToyOptions"


def test_a_bad_option_declaration_is_named_where_it_registers(sandbox):
    import inspect
    from dataclasses import make_dataclass

    from emml.models import Fusion, build_model, model_option, register_model
    from emml.models.registry import BUILD_ARGUMENTS

    def fusion(*fields):
        return type("Bad", (Fusion,), {"options": make_dataclass("BadOptions", fields)})

    with pytest.raises(ValueError, match="model 'bad': its option 'hidden' is one every model shares"):
        register_model("bad", "Bad", fusion(("hidden", int, model_option(3))))
    for reserved in ("width", "height", "vocab_size", "max_steps"):  # build_model's own arguments
        with pytest.raises(ValueError, match=f"model 'bad': its option '{reserved}' is an argument of every model"):
            register_model("bad", "Bad", fusion((reserved, int, model_option(3))))
    build = inspect.signature(build_model).parameters  # the reserved names follow build_model's signature
    assert set(BUILD_ARGUMENTS) == {p for p, v in build.items() if v.kind is v.POSITIONAL_OR_KEYWORD} - {"name"}
    with pytest.raises(ValueError, match="model 'bad': every field of BadOptions needs a default"):
        register_model("bad", "Bad", fusion(("gain", float)))
    with pytest.raises(ValueError, match="model 'bad': Bad.options=<class 'dict'> must be a dataclass type"):
        register_model("bad", "Bad", type("Bad", (Fusion,), {"options": dict}))
    with pytest.raises(ValueError, match=re.escape("name='gain' must be a plain word holding '{}' once")):
        model_option(1.0, name="gain")


def test_train_eval_and_diagnose_a_plugin_model(sandbox, toy, tracking, monkeypatch, no_leftovers):
    roots = ["--set", f"run_root={tracking['run_root']}", "--set", f"results_root={tracking['results_root']}"]
    short = [x for k, v in SHORT.items() if k != "frames" for x in ("--set", f"{k}={v}")]
    args = ["train", "--model", "toy", "--profile", "smoke", "--table", "plug", "--frames", "64", *roots, *short]
    bad = runner.invoke(app, ["--plugin", str(toy), *args, "--set", "model_options.gain=-1"])  # before any compute
    assert bad.exit_code == 2 and "ModelConfig.gain=-1 must be > 0" in bad.output, bad.output
    assert not Path(tracking["run_root"]).exists()
    result = runner.invoke(app, ["--plugin", str(toy), *args, "--set", "model_options.gain=2", "--json"])
    assert result.exit_code == 0, result.output
    run_dir = Path(json.loads(result.stdout)["run_dir"])
    assert run_dir.name.startswith("toy-easy-noaux-gain2-s0-smoke")  # the toy's own option, spelled from its file
    assert json.loads((run_dir / "results.json").read_text())["config"]["model_options"] == {"gain": 2}
    checkpoint = str(run_dir / "checkpoint.pt")
    scores = runner.invoke(app, ["eval", checkpoint, "--episodes", "1", "--json"])
    assert scores.exit_code == 0, scores.output
    assert set(json.loads(scores.stdout)) == {"sgn_train", "sgn_test", "eqa_train", "eqa_test"}
    diag = ["diagnose", checkpoint, "--episodes", "1", "--step0-episodes", "2", "--eqa-episodes", "0", "--json"]
    result = runner.invoke(app, diag)
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["attention_on_target"] is None  # the toy has no spatial attention map
    forget_plugins(monkeypatch)  # another process, without the plugin: the missing model is named
    missing = runner.invoke(app, ["eval", checkpoint, "--episodes", "1"])
    assert missing.exit_code == 2 and "unknown model name='toy'" in missing.output, missing.output
    assert "--plugin" in missing.output and "Traceback" not in missing.output


def test_run_a_table_of_ones_own_in_child_processes(sandbox, toy, tracking, monkeypatch, no_leftovers):
    short = ", ".join(f'"{k}" = {v}' for k, v in SHORT.items())
    table = toy.parent / "my_table.toml"
    table.write_text(TABLE.format(short=short, run_root=tracking["run_root"], results_root=tracking["results_root"]))
    env = {k: v for k, v in os.environ.items() if k != plugins.ENV_VAR}
    # a fresh `emml` process: its pool starts a forkserver child per run, which loads the plugin from EMML_PLUGINS
    command = [sys.executable, "-c", "from emml.cli import app; app()", "--plugin", "toy_fusion.py"]
    command += ["run", "my_table.toml", "--profile", "smoke", "--jobs", "2"]
    done = subprocess.run(command, cwd=toy.parent, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "1 trained, 0 already finished, 0 failed" in done.stdout, done.stdout
    rows = (Path(tracking["results_root"]) / "my_table" / "smoke.csv").read_text().splitlines()
    assert len(rows) == 2 and "toy-easy-noaux-s0-smoke" in rows[1]
    (run,) = (Path(tracking["run_root"]) / "my_table").iterdir()
    assert (run / "checkpoint.pt").exists() and (run / "results.json").exists()
    without = subprocess.run(command[:3] + command[5:], cwd=toy.parent, env=env, capture_output=True, text=True)
    assert without.returncode == 2 and "unknown model 'toy'" in without.stderr + without.stdout
    from emml.experiments.table_files import own_table
    from emml.report.tables import report_table

    monkeypatch.setenv(plugins.ENV_VAR, str(toy))  # its report, in this process
    rep = report_table(own_table(str(table)), "smoke", out=tracking["run_root"], **roots(tracking))
    assert any(c["n"] == 1 for c in rep["cells"])  # its own table has no paper numbers: ours only
    assert (Path(tracking["run_root"]) / "my_table-smoke.md").exists()


def roots(tracking) -> dict:
    return {"run_root": tracking["run_root"], "results_root": tracking["results_root"]}
