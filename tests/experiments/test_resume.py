def test_a_resume_line_keeps_what_was_given_and_leaves_the_defaults_out():
    """One spelling for every "resume with:" line (emml/experiments/resume.py): the plugins before the command, a
    true flag bare, a list repeated in order, and a default (None, False, 0, empty) left out."""
    from emml.experiments.resume import command_line

    options = [("--only", ["row=a b", "seed=0"]), ("--jobs", 0), ("--wait", True), ("--gpus", 0), ("--pack", 1)]
    options += [("--no-pin", False), ("--run-root", None), ("--device", "cuda")]
    assert command_line(["run", "table3"], options, ["my.plugin"]) == [
        "emml", "--plugin", "my.plugin", "run", "table3", "--only", "row=a b", "--only", "seed=0", "--wait",
        "--pack", "1", "--device", "cuda",
    ]  # fmt: skip
