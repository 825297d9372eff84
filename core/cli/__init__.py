"""The ``artgs`` command line: argparse only, one small module per command (``main`` is the entry)."""

from .app import main

__all__ = ["main"]
