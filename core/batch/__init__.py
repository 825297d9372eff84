"""``artgs batch``: one pipeline run per capture, on a local process pool or a Ray cluster.

- :mod:`.jobs`: the captures of a batch, their output folders, what is already done (resume).
- :mod:`.worker`: one capture in a worker (threads, log file, :func:`core.pipeline.run`, scores).
- :mod:`.local` / :mod:`.ray_pool`: the two ways of running workers (retrying dead ones).
- :mod:`.summary`: the per-capture table (CSV, JSON, printed); :mod:`.bar`: the batch's progress.
- :mod:`.run`: :func:`run_batch`, which ties them together.

Numpy-only at import time: torch and numba are loaded inside the workers, Ray only with ``--ray``.
"""
