"""Grouping the deviations of a table's runs: each line once, with the runs it holds for."""

from emml.report.deviations import ShownRun, summarise, who


def run(name, row, difficulty="easy", aux=True, cfg=None):
    from emml.config.profiles import profile_config
    from emml.experiments import fidelity

    config = fidelity.resolve((cfg or profile_config("quick", difficulty, model="ga", aux=aux)).to_dict())
    return ShownRun(name, {"row": row, "difficulty": difficulty, "aux": aux}, config, "saved")


def test_groups_are_named_by_what_they_share_or_by_name():
    runs = [run("a", "GA"), run("b", "GA", "hard"), run("c", "FiLM"), run("d", "FiLM", "hard")]
    assert who(runs, runs) == "all 4 runs"
    assert who(runs[:2], runs) == "the GA runs (2 of 4)"
    assert who([runs[0], runs[2]], runs) == "the Easy runs (2 of 4)"
    assert who(runs[:3], runs) == "3 of 4 runs: a, b, c"
    more = [*runs, run("e", "Concat"), run("f", "PACMAN")]
    assert who(more[:5], more) == "all but the PACMAN runs (5 of 6)"  # shorter than 'the Concat and FiLM and GA…'


def test_identical_lines_are_said_once():
    from emml.config.profiles import profile_config

    runs = [run("a", "GA"), run("b", "GA", "hard"), run("c", "GA", cfg=profile_config("paper", model="ga", aux=True))]
    d = summarise(runs)
    assert ("input 84×150 (paper 168×300, App. A)", "2 of 3 runs: a, b") in d.deviations
    assert ("frames 5M (paper 50M, §5.1)", "the Hard runs (1 of 3)") in d.deviations
    assert d.sources == "3 runs from their saved config (runs/<table>/<run>/results.json)"
