"""The engine's worker protocol: JSON-line event names and exit codes, defined once.

The ``artgs`` command (``--json``) writes one JSON object per line on stdout; the Blender add-on's
worker reads them. Both sides import these names from here.

- ``{"event": PROGRESS, "stage": S, "fraction": F, "message": M, "figures": {...}}``
- ``{"event": STAGE_DONE, "stage": S, "seconds": T, "figures": {...}}``
- ``{"event": LOG, "level": "info"|"warning", "message": M}``
- ``{"event": ERROR, "message": M}`` (then a non-zero exit)
- ``{"event": FINISHED, "outputs": {...}}``
"""

EVENT = "event"
PROGRESS = "progress"
STAGE_DONE = "stage_done"
LOG = "log"
ERROR = "error"
FINISHED = "finished"

#: Exit codes of the ``artgs`` command.
EXIT_OK = 0
EXIT_FAILED = 1      # an error that is not the input's fault
EXIT_BAD_INPUT = 2   # refused before work: the message names the file and field
EXIT_CANCELLED = 130  # SIGINT/SIGTERM (128 + SIGINT), as shells report Ctrl-C
