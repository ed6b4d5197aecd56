"""`python -m emml.cli …`: the `emml` command (the campaign re-executes itself this way)."""

from emml.cli import app

app()
