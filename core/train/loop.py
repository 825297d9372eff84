"""The optimisation loop shared by the stages: iterate a step, report progress, stop on a plateau.

A stage supplies the step (one optimiser update, returning its loss) and, for the progress
events, a function of the iteration giving the figures to show; the loop counts iterations,
reports every ``report_every`` of them (and at the end), checks for cancel on the others, and
stops early when the loss plateaus (:class:`Plateau`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..model.progress import Progress


@dataclass
class LoopResult:
    iterations: int
    stopped: str          # "cap" or "converged"
    final_loss: float     # mean loss of the last (partial) window; the previous one if empty


class Plateau:
    """Convergence test: the mean loss over each ``window`` iterations is compared with the
    previous window's; converged when it dropped by less than ``tol`` of it, checked only after
    iteration ``after`` (e.g. the end of densification, which raises the loss for a while).
    Disabled (``enabled=False``: a fixed iteration count) it only keeps the final loss."""

    def __init__(self, window: int, tol: float, after: int = 0, enabled: bool = True) -> None:
        self.window, self.tol, self.after, self.enabled = window, tol, after, enabled
        self.losses: list[float] = []
        self.previous = math.inf

    def add(self, it: int, loss: float) -> bool:
        """Record iteration ``it``'s loss; True when converged."""
        self.losses.append(loss)
        if len(self.losses) < self.window:
            return False
        cur = float(np.mean(self.losses))
        self.losses = []
        if self.enabled and it > self.after and self.previous - cur < self.tol * self.previous:
            return True
        self.previous = cur
        return False

    @property
    def final_loss(self) -> float:
        return float(np.mean(self.losses)) if self.losses else self.previous


def run_loop(step: Callable[[], float], start: int, cap: int, progress: Progress, stage: str, *,
             plateau: Plateau,
             figures: Callable[[], dict[str, float]] | None = None,
             report_every: int = 25) -> LoopResult:
    """Call ``step()`` (one update; returns its loss) from iteration ``start + 1`` to ``cap``.

    Every ``report_every`` iterations and at the last, a progress update of ``stage`` with the loss
    and ``figures()``; otherwise a cancel check. Stops early when ``plateau`` says converged.
    """
    it, stopped = start, "cap"
    while it < cap:
        loss = step()
        it += 1
        if it % report_every == 0 or it == cap:
            progress.update(stage, it / cap, f"iteration {it}/{cap}", loss=loss,
                            **(figures() if figures else {}))
        else:
            progress.check_cancel()
        if plateau.add(it, loss):
            stopped = "converged"
            break
    return LoopResult(it, stopped, plateau.final_loss)
