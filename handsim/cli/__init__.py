"""The ``handsim`` command-line program, one module per command group."""

from handsim.cli.main import main

__all__ = ["main"]
