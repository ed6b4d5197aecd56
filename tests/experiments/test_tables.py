"""The experiment registry: every reproduce/ TOML loads, tables expand to the paper's settings, bad files fail
naming the file and the key; the paper's numbers are complete."""

from pathlib import Path

import pandas as pd
import pytest

from emml.config.paths import REPRODUCE_DIR
from emml.experiments.table_files import list_tables, table_names, table_ref
from emml.experiments.tables import load_table
from emml.report.cells import paper_numbers
from emml.runs.naming import run_name

SEEDS = [0, 1, 2]


@pytest.mark.parametrize("name", list_tables())
def test_every_table_loads(name):
    table = load_table(name)
    assert table.status in ("active", "placeholder")
    if table.placeholder:
        assert table.runs(SEEDS) == []
    else:
        runs = table.runs(SEEDS)
        names = [r.run_name("quick") for r in runs]
        assert len(set(names)) == len(names), "run names must be unique within a table"
        for r in runs[:3]:
            assert r.to_config("smoke").validate().table == name


def test_every_toml_in_reproduce_is_a_known_kind():
    assert {p.stem for p in REPRODUCE_DIR.glob("*.toml")} == {"profiles", "claims", *list_tables()}
    assert list_tables() == ["table2", "table3", "table4", "table5"]


def test_table2_expands_to_28_settings_per_seed():
    table = load_table("table2")
    runs = table.runs(SEEDS)
    assert len(runs) == 28 * len(SEEDS)
    settings = {(r.model, r.difficulty, r.aux) for r in runs}
    assert len(settings) == 28
    assert {r.model for r in runs} == {"text_only", "image_only", "concat", "ga", "film", "pacman", "dual_attention"}
    assert table.columns()[0] == ("easy", False, "sgn_test") and len(table.columns()) == 8


def test_table3_expands_to_ablations_and_single_task_runs():
    table = load_table("table3")
    runs = table.runs([0])
    # 6 one-setting rows + DA single-task (SGN-only, EQA-only) = 8 settings, × No Aux/Aux
    assert len(runs) == 16
    assert {r.difficulty for r in runs} == {"easy"}
    names = {r.run_name("quick") for r in runs}
    assert "dual_attention-easy-noaux-noshaping-warm400000-s0-quick" in names  # No Aux: 400k to GA2 first (48)
    assert "da_no_ga2-easy-noaux-warm400000-s0-quick" in names  # one No Aux rule for every row (issue 61)
    assert "da_no_sa-easy-noaux-warm400000-s0-quick" in names  # its run under the paper's loss is retired
    assert "dual_attention-easy-aux-sgnonly-s0-quick" in names and "dual_attention-easy-aux-eqaonly-s0-quick" in names
    single = [r for r in runs if r.row == "DA Single-Task"]
    assert {(r.overrides["env.tasks"], r.metrics) for r in single} == {("sgn", ("sgn_test",)), ("eqa", ("eqa_test",))}
    cfg = next(r for r in runs if r.row == "w/o Reward Shaping").to_config("smoke")
    assert cfg.env.shaping is False and cfg.model == "dual_attention"
    multi = [r for r in runs if r.row == "DA Multi-Task"]  # Table 2's Dual-Attention runs, not trained twice
    assert {(r.table, r.run_name("quick")) for r in multi} == {
        ("table2", "dual_attention-easy-noaux-warm400000-s0-quick"),
        ("table2", "dual_attention-easy-aux-s0-quick"),
    }
    assert {r.table for r in runs if r.row != "DA Multi-Task"} == {"table3"}


def test_noaux_overrides_reach_the_no_aux_runs_only():
    """Issue 48: Dual-Attention's No Aux runs keep the answer loss to the GA2 gate for their first 400k frames; its Aux
    runs are the paper's. Issue 61: the baselines' No Aux runs take the same warm-up, under names that say it."""
    runs = [r for r in load_table("table2").runs([0]) if r.model == "dual_attention" and r.difficulty == "easy"]
    by_aux = {r.aux: r.to_config("quick") for r in runs}
    assert by_aux[False].model_options == {"answer_gate_frames": 400000} and not by_aux[True].model_options
    assert {r.aux: r.run_name("quick") for r in runs} == {
        False: "dual_attention-easy-noaux-warm400000-s0-quick",
        True: "dual_attention-easy-aux-s0-quick",
    }
    assert {r.aux: r.departures for r in runs} == {False: ("model_options.answer_gate_frames",), True: ()}
    table2 = load_table("table2").runs([0])
    easy = {r.model: r.run_name("quick") for r in table2 if r.difficulty == "easy" and not r.aux}
    assert easy["ga"] == "ga-easy-noaux-warm400000-s0-quick" and easy["film"] == "film-easy-noaux-warm400000-s0-quick"
    assert easy["text_only"] == "text_only-easy-noaux-s0-quick"  # its answer reads no image
    house = {r.model: r.run_name("quick") for r in load_table("table5").runs([0])}
    assert house["dual_attention"] == "dual_attention-house-noaux-warm400000-s0-quick"
    assert house["film"] == "film-house-noaux-warm400000-s0-quick"


NO_AUX_TABLES = ("table2", "table3", "table5")
"""The tables with No Aux rows: one warm-up for all of them (issue 61)."""


def _check_one_no_aux_schedule(load=load_table) -> None:
    """Every No Aux run of Tables 2, 3 and 5 whose answer reads the image (`Fusion.answer_warmup`) under the same
    warm-up, Text only under none, no Aux run under one; an AssertionError names the rows that differ."""
    from emml.models import MODELS

    schedules: dict[int, list[str]] = {}
    for name in NO_AUX_TABLES:
        for spec in load(name).runs([0]):
            frames = spec.to_config("quick").model_options.get("answer_gate_frames", 0)
            where = f"{name} {spec.row!r} ({spec.difficulty}, {'Aux' if spec.aux else 'No Aux'})"
            if spec.aux:
                assert frames == 0, f"{where}: an Aux run under a warm-up of {frames:,} frames"
            elif MODELS[spec.model].fusion.answer_warmup:
                schedules.setdefault(frames, []).append(where)
            else:
                assert frames == 0, f"{where}: its answer reads no image, yet a warm-up of {frames:,} frames"
    assert len(schedules) == 1, "No Aux rows under different schedules: " + "; ".join(
        f"{frames:,} frames: {', '.join(rows)}" for frames, rows in schedules.items()
    )
    return set(schedules)


def test_every_no_aux_row_of_tables_2_3_and_5_trains_under_one_schedule():
    """Issue 61, "No Aux like for like": the warm-up is a property of the No Aux setting, not of a row: every No Aux
    row of Tables 2, 3 and 5 trains under the same one, issue 48's N (it stays unless two seeds say otherwise)."""
    assert _check_one_no_aux_schedule() == {400_000}


def test_the_one_schedule_check_fails_on_a_row_that_differs(tmp_path):
    """The check above, on Table 2 with GA's No Aux row back on the paper's loss: it names the row."""
    ga = 'model = "ga"\nnoaux_overrides = { "model_options.answer_gate_frames" = 400000 }\n'
    text = (REPRODUCE_DIR / "table2.toml").read_text()
    assert ga in text
    (tmp_path / "table2.toml").write_text(text.replace(ga, 'model = "ga"\n'))

    def load(name):
        return load_table(name, tmp_path / "table2.toml") if name == "table2" else load_table(name)

    with pytest.raises(AssertionError, match=r"0 frames: table2 'GA' \(easy, No Aux\), table2 'GA' \(hard, No Aux\)"):
        _check_one_no_aux_schedule(load)


def test_a_bad_noaux_override_fails_naming_the_row(tmp_path):
    text = GOOD.replace('"dual_attention"', '"ga"\nnoaux_overrides = { "model_options.answer_grad" = "gate" }')
    with pytest.raises(ValueError, match=r"rows\[\d\]\.noaux_overrides") as err:
        load_table("tableX", _write(tmp_path, text))
    assert "answer_grad" in str(err.value)


@pytest.mark.parametrize(
    "borrow, what",
    [
        ('from_table = "table9"', "'table9' is not allowed"),
        ('from_table = "tableX"', "'tableX' is not allowed"),  # itself
        ('from_table = "table2"\noverrides = { "env.shaping" = false }', "no row of model 'dual_attention'"),
        ('from_table = "table2"\nnoaux_overrides = { "ppo.lr" = 0.001 }', "noaux_overrides {'ppo.lr': 0.001}"),
        # Table 3's DA Multi-Task row is this setting, but borrows it from Table 2 itself: no chain
        ('from_table = "table3"\nnoaux_overrides = { "model_options.answer_gate_frames" = 400000 }', "its own runs"),
        ('from_table = "table2"\nmetric_overrides = { sgn_test = { "env.tasks" = "sgn" } }', "only a plain row"),
    ],
)
def test_a_row_borrows_only_a_run_another_table_trains(tmp_path, borrow, what):
    path = _write(tmp_path, GOOD.replace('model = "dual_attention"', f'model = "dual_attention"\n{borrow}'))
    with pytest.raises(ValueError, match=what) as err:
        load_table("tableX", path)
    assert "rows[0].from_table" in str(err.value)


def test_run_spec_takes_seeds_and_size_from_the_profile():
    spec = load_table("table2").runs([7])[-1]  # Dual-Attention, Hard, Aux
    cfg = spec.to_config("paper")
    assert (cfg.seed, cfg.aux, cfg.env.difficulty, cfg.frames, cfg.profile) == (7, True, "hard", 50_000_000, "paper")
    assert run_name(cfg) == "dual_attention-hard-aux-s7-paper"


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "tableX.toml"
    path.write_text(text)
    return path


GOOD = """
title = "t"
paper_label = "tab:x"
status = "active"
[columns]
difficulties = ["easy"]
aux = [false]
metrics = { SGN = "sgn_test" }
[[rows]]
label = "DA"
model = "dual_attention"
"""


def test_a_good_fixture_loads(tmp_path):
    assert len(load_table("tableX", _write(tmp_path, GOOD)).runs([0])) == 1


def test_a_table_is_validated_once_per_content_and_read_again_when_its_file_changes(tmp_path, monkeypatch):
    """`LOADED`: a report reads each table once per claim; the second load of the same bytes is the first's Table,
    an edited file (the same size, the same second) or an edited table it may borrow from is parsed and checked again,
    a bad edit fails again."""
    import emml.experiments.tables as tables

    parsed = []
    monkeypatch.setattr(tables, "_parse", lambda name, path, data: parsed.append(data["title"]) or data["title"])
    path = _write(tmp_path, GOOD)
    assert load_table("tableX", path) == "t" and load_table("tableX", path) == "t" and parsed == ["t"]
    path.write_text(GOOD.replace('title = "t"', 'title = "u"'))
    assert load_table("tableX", path) == "u" and parsed == ["t", "u"]
    other = tmp_path / "tableB.toml"  # a table of reproduce/ it may borrow runs from (`_from_table`)
    monkeypatch.setattr(tables, "list_tables", lambda: ["tableB"])
    monkeypatch.setattr(tables, "table_path", lambda name: tmp_path / f"{name}.toml")
    other.write_text("b = 1")
    assert load_table("tableX", path) == "u" and parsed == ["t", "u", "u"]
    assert load_table("tableX", path) == "u" and parsed == ["t", "u", "u"]
    other.write_text("b = 2")
    assert load_table("tableX", path) == "u" and parsed == ["t", "u", "u", "u"]
    path.write_text(GOOD.replace('title = "t"', 'title = "t'))
    for _ in range(2):
        with pytest.raises(ValueError, match="not valid TOML"):
            load_table("tableX", path)


@pytest.mark.parametrize(
    "old, new, key, what",
    [
        ('model = "dual_attention"', 'model = "transformer"', "rows[0].model", "transformer"),
        ('status = "active"', 'status = "done"', "status", "placeholder"),
        ('difficulties = ["easy"]', 'difficulties = ["medium"]', "columns.difficulties", "medium"),
        ('{ SGN = "sgn_test" }', '{ SGN = "sgn_val" }', "columns.metrics.SGN", "sgn_val"),
        ('label = "DA"', 'lable = "DA"', "rows[0].lable", "unknown key"),
        (
            'model = "dual_attention"',
            'model = "dual_attention"\noverrides = { "env.colour" = 1 }',
            "rows[0].overrides",
            "colour",
        ),
        (
            'model = "dual_attention"',
            'model = "dual_attention"\noverrides = { "env.tasks" = "all" }',
            "rows[0].overrides",
            "tasks",
        ),
        ('title = "t"\n', "", "title", "missing"),
        ("aux = [false]", 'aux = ["no"]', "columns.aux", "booleans"),
    ],
)
def test_malformed_toml_names_file_and_key(tmp_path, old, new, key, what):
    path = _write(tmp_path, GOOD.replace(old, new))
    with pytest.raises(ValueError) as err:
        load_table("tableX", path)
    msg = str(err.value)
    assert str(path) in msg and repr(key) in msg and what in msg


def test_invalid_toml_syntax_names_file(tmp_path):
    path = _write(tmp_path, GOOD + "\n[[rows]\n")
    with pytest.raises(ValueError, match="tableX.toml"):
        load_table("tableX", path)


def test_rows_colliding_on_run_name_are_rejected(tmp_path):
    """Rows that differ only in how their runs run (threads) are one run; another learning rate is another run
    (its name says it: emml/runs/rundir.py)."""
    extra = '\n[[rows]]\nlabel = "DA {}"\nmodel = "dual_attention"\noverrides = {{ {} }}\n'
    with pytest.raises(ValueError, match="same run name"):
        load_table("tableX", _write(tmp_path, GOOD + extra.format("threads", '"threads" = 1')))
    table = load_table("tableX", _write(tmp_path, GOOD + extra.format("lr", '"ppo.lr" = 0.1')))
    assert any(spec.run_name("smoke").endswith("+ppo.lr=0.1") for spec in table.runs([0]))


def test_placeholder_declares_no_runs(tmp_path):
    text = 'title = "t"\npaper_label = "x"\nstatus = "placeholder"\n[[rows]]\nlabel = "a"\nmodel = "ga"\n'
    with pytest.raises(ValueError, match="placeholder"):
        load_table("tableX", _write(tmp_path, text))


def test_unknown_table_lists_the_known_ones():
    with pytest.raises(ValueError, match="table2.*'experiments/eqa_gate'"):
        load_table("table9")


def test_an_experiment_loads_by_the_name_a_campaign_step_gives_it():
    """`emml run experiments/eqa_gate` and a campaign step's table = "experiments/eqa_gate" load
    reproduce/experiments/eqa_gate.toml under the plain name its runs and results are filed by."""
    table = load_table("experiments/eqa_gate")
    assert table.name == "eqa_gate" and table.path == REPRODUCE_DIR / "experiments" / "eqa_gate.toml"
    assert load_table("eqa_gate").name == "eqa_gate"  # loaded once, found again by that name (the launcher)
    with pytest.raises(
        ValueError, match="table='experiments/nope' is unknown; the experiments are .*'experiments/eqa_gate'"
    ):
        load_table("experiments/nope")


@pytest.mark.parametrize("name", table_names())
def test_a_table_file_is_shown_as_the_name_that_loads_it(name, tmp_path):
    """Report captions print `emml run <table_ref>`: it must load the same table (experiments/<x> or the file)."""
    ref = table_ref(load_table(name).path)
    assert ref == name if name.startswith("experiments/") else ref == f"reproduce/{name}.toml"
    outside = tmp_path / "mine.toml"
    assert table_ref(outside) == str(outside.resolve())  # not under the project: as given


@pytest.mark.parametrize("name, cells", [("table2", 56), ("table3", 28), ("table4", 16), ("table5", 28)])
def test_paper_csvs_are_complete(name, cells):
    df = paper_numbers(name)
    assert list(df.columns) == ["row", "difficulty", "aux", "metric", "value"]
    assert len(df) == cells
    assert not df.duplicated(["row", "difficulty", "aux", "metric"]).any()
    values = pd.to_numeric(df["value"])
    assert values.between(0, 1).all()
    table = load_table(name)
    if not table.placeholder:  # every cell of the registry has the paper's number, and vice versa
        declared = {(r.label, d, a, m) for r in table.rows if not r.extra for d, a, m in table.columns()}
        assert declared == set(zip(df["row"], df["difficulty"], df["aux"], df["metric"]))


def test_paper_numbers_are_kept_as_printed():
    df = paper_numbers("table2").set_index(["row", "difficulty", "aux", "metric"])["value"]
    assert df[("Text only", "easy", False, "sgn_test")] == "0.2"
    assert df[("Dual-Attention", "hard", True, "eqa_test")] == "0.59"
    assert df[("PACMAN", "hard", False, "eqa_test")] == "0.33"
    t3 = paper_numbers("table3").set_index(["row", "aux", "metric"])["value"]
    assert t3[("w/o GA2", True, "sgn_test")] == "0.97" and t3[("DA Single-Task", False, "eqa_test")] == "0.31"


MORE = (
    'model = "dual_attention"\nmore_seeds = [{ profile = "quick", difficulty = "easy", aux = false, seeds = [3, 4] }]'
)


def test_more_seeds_add_a_settings_seeds_under_their_profile_only(tmp_path):
    """`more_seeds` (issue 82): the setting it names trains the profile's seeds, then its own, under that profile
    only; another profile, difficulty or aux column plans the profile's seeds alone."""
    text = GOOD.replace('difficulties = ["easy"]', 'difficulties = ["easy", "hard"]').replace(
        "[false]", "[false, true]"
    )
    table = load_table("tableX", _write(tmp_path, text.replace('model = "dual_attention"', MORE)))
    seeds = {
        (r.difficulty, r.aux): [
            s.seed for s in table.runs([0, 1], "quick") if (s.difficulty, s.aux) == (r.difficulty, r.aux)
        ]
        for r in table.runs([0])
    }
    assert seeds == {
        ("easy", False): [0, 1, 3, 4],
        ("easy", True): [0, 1],
        ("hard", False): [0, 1],
        ("hard", True): [0, 1],
    }
    assert [s.seed for s in table.runs([0, 1], "paper")] == [0, 1] * 4
    assert [s.seed for s in table.runs([0, 3], "quick") if (s.difficulty, s.aux) == ("easy", False)] == [0, 3, 4]


def test_the_stated_model_trains_five_easy_aux_seeds_at_quick():
    """Table 2's Dual-Attention, Easy · Aux: seeds 0-4 at the quick profile (issue 82); Table 3's DA Multi-Task
    reads the same five runs; the paper profile plans its own seeds only."""
    from emml.config.profiles import profile_seeds

    def easy_aux(table: str, profile: str, row: str) -> list[int]:
        runs = load_table(table).runs(profile_seeds(profile), profile)
        return [r.seed for r in runs if (r.row, r.difficulty, r.aux) == (row, "easy", True)]

    assert easy_aux("table2", "quick", "Dual-Attention") == [0, 1, 2, 3, 4]
    assert easy_aux("table3", "quick", "DA Multi-Task") == [0, 1, 2, 3, 4]
    assert easy_aux("table2", "paper", "Dual-Attention") == profile_seeds("paper")


@pytest.mark.parametrize(
    "entry, key, what",
    [
        ('{ profile = "quik", difficulty = "easy", aux = false, seeds = [3] }', "profile", "quik"),
        ('{ profile = "quick", difficulty = "medium", aux = false, seeds = [3] }', "difficulty", "medium"),
        ('{ profile = "quick", difficulty = "easy", aux = "no", seeds = [3] }', "aux", "true or false"),
        ('{ profile = "quick", difficulty = "easy", aux = false, seeds = [-1] }', "seeds", "non-negative"),
        ('{ profile = "quick", difficulty = "easy", aux = false, seeds = [3, 3] }', "seeds", "twice"),
        ('{ profile = "quick", difficulty = "easy", aux = false }', "seeds", "missing"),
        ('{ profile = "quick", difficulty = "easy", aux = false, seeds = [3], seed = 4 }', "seed", "unknown key"),
    ],
)
def test_a_bad_more_seeds_entry_names_its_key(tmp_path, entry, key, what):
    path = _write(
        tmp_path, GOOD.replace('model = "dual_attention"', f'model = "dual_attention"\nmore_seeds = [{entry}]')
    )
    with pytest.raises(ValueError) as err:
        load_table("tableX", path)
    assert repr(f"rows[0].more_seeds[0].{key}") in str(err.value) and what in str(err.value)
