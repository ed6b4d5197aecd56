"""`python -m emml …`: the `emml` command."""

from emml.cli import app

app()
