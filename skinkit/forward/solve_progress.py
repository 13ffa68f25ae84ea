"""Progress of the finite-element model's protocol solves, from whichever process runs them.

A solve in the caller's process reports each output step directly; a solve in a worker process
puts ``(protocol, fraction)`` on a queue the pool was made with (:func:`init_worker`), which the
parent drains while it waits for the results (:func:`gather`). Either way the fractions end in
:class:`SolveProgress`, which weighs the protocols by their steps and passes one fraction of the
whole prediction on to :func:`skinkit.forward.stages.report`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from skinkit.forward import stages

#: how often [s] the parent drains the workers' step reports while it waits for their results
POLL_S = 0.5
#: in a worker process: where its solves report their steps, or None (not a reporting pool)
_STEP_QUEUE: Any = None


def init_worker(queue: Any) -> None:
    """Worker process initialiser: keep the queue the parent reads step reports from."""
    global _STEP_QUEUE
    _STEP_QUEUE = queue


def step_reporter(name: str, times: np.ndarray, on_fraction: Callable[[float], None] | None
                  ) -> Callable[[float], None] | None:
    """The solver's ``progress(t)`` for protocol ``name`` solved at ``times`` [s]: the fraction
    solved, to ``on_fraction`` (a solve in the caller's process) or to the parent through the
    worker's queue; None when no one listens (a Dask worker)."""
    end = float(times[-1]) if len(times) else 0.0
    if end <= 0:
        return None
    if on_fraction is not None:
        return lambda t: on_fraction(min(t / end, 1.0))
    queue = _STEP_QUEUE
    if queue is None:
        return None
    return lambda t: queue.put((name, min(t / end, 1.0)))


class SolveProgress:
    """The fraction of a prediction's solver steps done over all its protocols, each weighted by
    its number of output steps (jobs with ``name`` and ``times``), reported as it grows."""

    def __init__(self, jobs: Sequence[Any]) -> None:
        self.weights = {j.name: max(len(j.times), 1) for j in jobs}
        self.done: dict[str, float] = dict.fromkeys(self.weights, 0.0)
        self.total = float(sum(self.weights.values()))

    def __call__(self, name: str, fraction: float) -> None:
        """Protocol ``name`` is ``fraction`` (0..1) solved."""
        self.done[name] = max(self.done.get(name, 0.0), float(fraction))
        solved = sum(1 for f in self.done.values() if f >= 1.0)
        overall = sum(self.weights[n] * f for n, f in self.done.items()) / self.total
        stages.report(overall, f"{solved}/{len(self.done)} protocols solved")


def gather(futures: Sequence[Any], queue: Any, tracker: SolveProgress) -> dict[str, dict[str, Any]]:
    """The results of ``futures`` (each a dict with ``name``) in their order, passing the workers'
    step reports from ``queue`` on to ``tracker`` meanwhile; a failed solve raises at once."""
    from concurrent.futures import FIRST_COMPLETED, wait

    pending = set(futures)
    while pending:
        done, pending = wait(pending, timeout=POLL_S, return_when=FIRST_COMPLETED)
        while queue is not None and not queue.empty():
            tracker(*queue.get())
        for f in done:
            tracker(f.result()["name"], 1.0)
    return {r["name"]: r for r in (f.result() for f in futures)}


__all__ = ["POLL_S", "SolveProgress", "gather", "init_worker", "step_reporter"]
