"""The articulation optimisation stage (``artgs optimise``): see :mod:`.stage`."""

from ...model.registry import OptimiseOptions
from .stage import optimise, run

__all__ = ["OptimiseOptions", "optimise", "run"]
