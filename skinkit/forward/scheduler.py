"""Reaching a Dask scheduler before any work is sent to it: its address parsed and its port
tried, so that a mistyped or unreachable scheduler is refused at once, in one line naming the
address, instead of after the client's own retries."""

from __future__ import annotations

import socket

from skinkit.errors import SkinkitError

#: seconds to wait for the scheduler's port to accept a connection
CONNECT_TIMEOUT_S = 3.0


def check_scheduler(address: str, option: str = "--scheduler", *,
                    timeout_s: float = CONNECT_TIMEOUT_S) -> str:
    """``address`` (``tcp://host:port``, ``host:port``, or another network scheme Dask knows)
    when it parses and its host accepts a connection on its port within ``timeout_s`` [s].
    Raises a one-line :class:`SkinkitError` naming ``option`` and the address otherwise."""
    where = f"{option} {address!r}"
    if not address.strip():
        raise SkinkitError(f"{where}: expected a Dask scheduler address (e.g. tcp://127.0.0.1:8786)")
    try:
        from distributed.comm.addressing import get_address_host_port
    except ImportError:
        raise SkinkitError(f"{where}: needs dask.distributed (pip install 'skinkit[cluster]')") from None
    try:
        host, port = get_address_host_port(address.strip())
    except (ValueError, TypeError) as exc:
        raise SkinkitError(f"{where}: not a Dask scheduler address ({exc}); expected e.g. "
                           "tcp://127.0.0.1:8786") from None
    if not host or not 0 < int(port) < 65536:
        raise SkinkitError(f"{where}: not a Dask scheduler address (no host or no port 1-65535); "
                           "expected e.g. tcp://127.0.0.1:8786")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s):
            pass
    except OSError as exc:
        why = (f"no answer within {timeout_s:g} s" if isinstance(exc, TimeoutError)
               else (exc.strerror or str(exc)))
        raise SkinkitError(f"{where}: cannot reach the Dask scheduler at {host}:{port} ({why}); "
                           f"start it, or leave out {option}") from None
    return address.strip()


__all__ = ["CONNECT_TIMEOUT_S", "check_scheduler"]
