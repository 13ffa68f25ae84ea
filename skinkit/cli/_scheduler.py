"""The ``--scheduler ADDRESS`` option of the commands that run work on a Dask cluster: the address
is parsed and its host and port reached before any work starts, so a mistyped or unreachable
scheduler is refused at once in one line naming the option and the address, whatever the
command and whether or not its model would have used the cluster."""

from __future__ import annotations

from typing import Any

import click

from skinkit.forward.scheduler import CONNECT_TIMEOUT_S, check_scheduler


def scheduler_callback(ctx: click.Context, param: click.Parameter, value: Any) -> str | None:
    """Click callback of a ``--scheduler`` option: :func:`check_scheduler` when it is given."""
    if value is None:
        return None
    return check_scheduler(str(value), "--scheduler")


__all__ = ["CONNECT_TIMEOUT_S", "check_scheduler", "scheduler_callback"]
