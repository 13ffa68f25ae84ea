"""Benchmark cases run in this process, in a pool of processes, or on a Dask cluster."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from skinkit.bench.gap_cases import BenchmarkError, mark_worker
from skinkit.errors import SkinkitError


class TaskPool:
    """Tasks run in this process (``parallel <= 1``), in a pool of processes, or on a Dask cluster."""

    def __init__(self, parallel: int, scheduler: str | None) -> None:
        self.client = self.executor = None
        if scheduler:
            from dask.distributed import Client

            from skinkit.forward.scheduler import check_scheduler

            try:    # a caller that skips the command line's check still gets a prompt, named refusal
                check_scheduler(scheduler, "scheduler")
                self.client = Client(scheduler, timeout="10s", set_as_default=False)
            except SkinkitError as exc:
                raise BenchmarkError(str(exc)) from None
            except (OSError, TimeoutError, ValueError) as exc:
                raise BenchmarkError(f"scheduler {scheduler!r}: cannot reach the Dask scheduler "
                                     f"({exc})") from None
        elif parallel > 1:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            self.executor = ProcessPoolExecutor(parallel, mp_context=multiprocessing.get_context("spawn"),
                                                initializer=mark_worker)

    def map(self, fn: Callable[[Any], Any], items: Sequence[Any], done: Callable[[Any], None]) -> list[Any]:
        """``fn`` over ``items`` (results in the items' order); ``done(result)`` as each finishes."""
        if self.client is not None:
            from dask.distributed import as_completed

            futs = [self.client.submit(fn, it, pure=False) for it in items]
            index = {f.key: i for i, f in enumerate(futs)}
            out: list[Any] = [None] * len(items)
            for f in as_completed(futs):
                out[index[f.key]] = r = f.result()
                done(r)
            return out
        if self.executor is not None:
            from concurrent.futures import as_completed as done_order

            futs = {self.executor.submit(fn, it): i for i, it in enumerate(items)}
            out = [None] * len(items)
            for f in done_order(futs):
                out[futs[f]] = r = f.result()
                done(r)
            return out
        res = []
        for it in items:
            res.append(fn(it))
            done(res[-1])
        return res

    def close(self) -> None:
        """Shut the process pool down and leave the cluster (its scheduler keeps running)."""
        if self.executor is not None:
            self.executor.shutdown()
        if self.client is not None:
            self.client.close()


__all__ = ["TaskPool"]
