"""``python -m artgs``: the same as the ``artgs`` command."""

import sys

from .core.cli import main

if __name__ == "__main__":   # not when a spawned worker process imports the main module
    sys.exit(main())
