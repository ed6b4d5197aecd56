"""A run's one owner (emml/runs/rundir.py): names, identity, paths, and reports that read runs without torch."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from emml.config.paths import project_root
from emml.config.profiles import profile_config
from emml.config.schema import TrainConfig
from emml.runs.naming import run_name, swept
from emml.runs.rundir import CHECKPOINT, config_of, path_of, run_dir, variant_dir


def test_every_committed_run_dir_keeps_its_name():
    """Run dirs written before the identity was declared (the committed reference runs) resolve to themselves."""
    dirs = sorted(p.parent for p in (project_root() / "runs").glob("*/*/results.json")) + sorted(
        p.parent for p in (project_root() / "runs").glob("*/*/*/results.json")
    )
    assert dirs, "no committed run dir to check"
    for d in dirs:
        cfg = TrainConfig.from_dict(json.loads((d / "results.json").read_text())["config"])
        assert run_name(cfg) == d.name, (d, swept(cfg))


def test_every_committed_run_dir_in_flight_keeps_its_name():
    """Issue 65: the run dirs still training (a checkpoint, no results.json yet: e.g. Table 3's `…-warm400000-…` No Aux
    runs) resolve to themselves too, under the exact spelling of numbers (`emml.runs.naming.spell`)."""
    root = project_root() / "runs"
    dirs = [p.parent for p in sorted(root.glob("**/checkpoint.pt")) if not (p.parent / "results.json").exists()]
    assert dirs, "no committed run dir in flight to check"
    for d in dirs:
        cfg = config_of(d)
        assert run_name(cfg) == d.name, (d, swept(cfg))


def test_numbers_in_a_name_are_spelled_exactly_and_one_it_cannot_hold_is_refused():
    """Issue 65: `f"{value:g}"` named answer_gate_frames=1000001 'warm1e+06' (then 1000002 was refused as a run of
    another config) and accepted 10**20 ('warm1e+20'). Integers are spelled in full, floats exactly (as before when
    `:g` reads back as the same float), a non-finite value or an unbounded frame count is refused by `validate`."""
    import math

    import pytest

    from emml.runs.naming import spell

    def name(**options):
        sets = {f"model_options.{k}": v for k, v in options.items()}
        return run_name(profile_config("quick", "easy", sets, model="dual_attention", table="table2").validate())

    assert name(answer_gate_frames=1000001) == "dual_attention-easy-noaux-warm1000001-s0-quick"
    assert name(answer_gate_frames=1000002) == "dual_attention-easy-noaux-warm1000002-s0-quick"
    assert name(answer_gate_frames=400000) == "dual_attention-easy-noaux-warm400000-s0-quick"  # as committed
    assert name(state_temperature=0.25) == "dual_attention-easy-noaux-xs0.25-s0-quick"
    assert name(state_temperature=0.1234567) != name(state_temperature=0.1234568)
    assert [spell(v) for v in (1e-05, 3e-4, 1000001, 2.0, 1e22)] == ["1e-05", "0.0003", "1000001", "2", "1e+22"]
    with pytest.raises(ValueError, match=r"^model_options.answer_gate_frames=100000000000000000000 must be a whole"):
        name(answer_gate_frames=10**20)
    with pytest.raises(ValueError, match=r"^frames=100000000000 must be a whole number of frames from 0 to "):
        profile_config("quick", "easy", {"frames": 10**11}).validate()
    with pytest.raises(ValueError, match=r"^model_options.state_temperature=nan: .*a run name cannot hold it"):
        name(state_temperature=math.nan)


def test_a_field_a_profile_does_not_set_names_its_value_and_a_long_list_a_digest():
    base = profile_config("quick")
    assert run_name(base) == "dual_attention-easy-noaux-s0-quick" and swept(base) == {}
    lr = profile_config("quick", "easy", {"ppo.lr": 3e-4})
    assert run_name(lr) == "dual_attention-easy-noaux-s0-quick+ppo.lr=0.0003"
    many = profile_config("quick", "easy", {"ppo.lr": 3e-4, "ppo.clip_coef": 0.1, "env.frame_skip": 4, "ppo.epochs": 3})
    assert run_name(many).startswith("dual_attention-easy-noaux-s0-quick+x") and len(run_name(many)) < 60
    assert run_name(many) != run_name(profile_config("quick", "easy", {"ppo.lr": 3e-4, "ppo.clip_coef": 0.3}))


def test_the_no_aux_run_beside_an_aux_run_is_found_from_its_config(tmp_path):
    aux = profile_config("quick", aux=True, table="table2")
    there = variant_dir(aux, tmp_path, aux=False)
    assert there == tmp_path / "table2" / "dual_attention-easy-noaux-s0-quick"
    rooted = profile_config("quick", "easy", {"run_root": str(tmp_path)}, aux=True, table="table2")
    assert path_of(tmp_path, "table2", run_name(aux)) == run_dir(rooted)
    assert config_of(tmp_path / "none") is None and CHECKPOINT == "checkpoint.pt"


def test_the_report_tables_and_the_run_owner_import_no_torch():
    code = "import sys, emml.runs.rundir, emml.report.tables, emml.report.index; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=Path(project_root()))
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_a_run_setting_only_shared_model_options_is_named_without_the_model_registry():
    """Issue 52 (4): the name parts of a model's own options come from its fusion's declaration (the registry, which
    imports torch); a run that sets none is named from the configs alone."""
    code = (
        "import sys; from emml.config.profiles import profile_config; from emml.runs.rundir import run_name; "
        "print(run_name(profile_config('quick', 'easy', {'model_options.sentence_readout': 'mean'})), "
        "'torch' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=Path(project_root()))
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["dual_attention-easy-noaux-sentmean-s0-quick", "False"]


def test_the_model_options_name_parts_come_from_their_declarations():
    """The shared options' parts, then the fusion's, each in declaration order: every committed name keeps its
    spelling (`test_every_committed_run_dir_keeps_its_name`); a state temperature beside a sentence readout, which
    no run has set, now follows it."""
    over = {
        "model_options.answer_grad": "gate",
        "model_options.eq1_words": "content",
        "model_options.sentence_activation": "softplus",
        "model_options.sentence_readout": "mean",
    }
    cfg = profile_config("quick", "easy", over, aux=True)
    assert run_name(cfg) == "dual_attention-easy-aux-sentmean-xsentsoftplus-eq1content-ansgate-s0-quick"
    cfg = profile_config("quick", "easy", {"model_options.state_temperature": 0.25, "model_options.eq1_words": "all"})
    assert run_name(cfg) == "dual_attention-easy-noaux-xs0.25-s0-quick" and swept(cfg) == {}
    both = {"model_options.state_temperature": 0.25, "model_options.sentence_readout": "mean"}
    assert run_name(profile_config("quick", "easy", both)) == "dual_attention-easy-noaux-sentmean-xs0.25-s0-quick"
    unnamed = profile_config("quick", "easy", {"model_options.state_scale": False})  # declared without a name part
    assert run_name(unnamed) == "dual_attention-easy-noaux-s0-quick+model_options.state_scale=False"
