"""Commands registered on multilat.cli.app.app (filled in by its owner)."""

from multilat.cli.app import app  # noqa: F401
