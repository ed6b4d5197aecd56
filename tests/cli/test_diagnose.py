"""`emml diagnose --gate [--record]` (emml/cli/diagnose.py): the question gate's figures of a checkpoint, without an
engine, and appended to a finished run's metrics.csv."""

import json

from typer.testing import CliRunner

from emml.cli import app
from emml.eval.diagnose_gate import diagnose_gate, scalars
from tests.eval.test_diagnose_gate import _env, _run_dir

runner = CliRunner()


def test_the_gate_of_a_checkpoint_is_printed_and_recorded(tmp_path):
    rdir, model = _run_dir(tmp_path)
    expected = diagnose_gate(model, _env())
    shown = runner.invoke(app, ["diagnose", str(rdir / "checkpoint.pt"), "--gate", "--json"])
    assert shown.exit_code == 0, shown.output
    data = json.loads(shown.stdout)
    assert data["gate_on_attribute"] == expected["gate_on_attribute"] and data["gate_dead"] == expected["gate_dead"]
    assert "diag/gate" not in (rdir / "metrics.csv").read_text()  # shown, not recorded
    text = runner.invoke(app, ["diagnose", str(rdir / "checkpoint.pt"), "--gate", "--record"])
    assert text.exit_code == 0, text.output
    assert f"mass on the answer's attribute {expected['gate_on_attribute']:.2f}" in text.stdout
    assert f"{len(scalars(expected))} figures appended at frame 3,200" in text.stdout
    again = runner.invoke(app, ["diagnose", str(rdir / "checkpoint.pt"), "--gate", "--record"])
    assert "nothing appended" in again.stdout


def test_record_without_gate_and_a_run_in_flight_fail_in_one_line(tmp_path):
    rdir, _ = _run_dir(tmp_path, finished=False)
    alone = runner.invoke(app, ["diagnose", str(rdir / "checkpoint.pt"), "--record"])
    assert alone.exit_code == 2 and "--record appends the gate figures: only with --gate" in alone.output
    flight = runner.invoke(app, ["diagnose", str(rdir / "checkpoint.pt"), "--gate", "--record"])
    assert flight.exit_code == 2 and "its checkpoint is not finished (frame 3,200)" in flight.output
