"""The articulation optimisation stage (``artgs optimise``): see :mod:`.stage`."""

from .stage import OptimiseOptions, optimise, run

__all__ = ["OptimiseOptions", "optimise", "run"]
