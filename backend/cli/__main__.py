"""`python -m backend.cli`: the same commands as `dexlabel`."""

from backend.cli import app

app()
