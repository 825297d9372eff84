"""``python -m artgs``: the same as the ``artgs`` command."""

import sys

from .core.cli import main

sys.exit(main())
