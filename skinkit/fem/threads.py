"""BLAS threading control for the batched small-matrix products of the assembly.

Thousands of small per-element products gain nothing from BLAS threads and lose a lot when
the cores are shared (OpenBLAS threads spin): measured on the two-core machine, one batched
element-tangent product took 0.84 s threaded against 0.033 s single-threaded. The sparse
direct solver keeps its own threads.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

_controller = None


def warm() -> None:
    """Build the thread-pool controller now (it inspects every loaded library, ~tens of ms)
    so that the first assembly of a solve does not pay for it."""
    global _controller
    if _controller is None:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:
            return
        _controller = ThreadpoolController()


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Limit BLAS (OpenBLAS/MKL through NumPy) to one thread inside the block."""
    global _controller
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:  # without threadpoolctl the products still run, only slower
        yield
        return
    if _controller is None:
        _controller = ThreadpoolController()
    with _controller.limit(limits=1, user_api="blas"):
        yield
