"""`python -m emml` (emml/__main__.py) runs the `emml` command (issue 54)."""

import subprocess
import sys


def test_python_dash_m_emml_runs_the_command():
    out = subprocess.run([sys.executable, "-m", "emml", "--help"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "Usage: python -m emml" in out.stdout, out.stderr
