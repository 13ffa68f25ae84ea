"""Acquisition: run named protocols through a driver plugin into an experiment file, or stream
records already in memory into one block by block, as a driver would."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from skinkit import registry
from skinkit.schemas import RobotRecord
from skinkit.store import create_experiment, open_experiment


def _quiet(step: str, fraction: float) -> None:
    pass


def stream_records(path: Path, records: list[RobotRecord], block: int,
                   progress: Callable[[str, float], None] = _quiet, append: bool = False) -> None:
    """Write ``records`` into a new experiment file ``path`` (``append``: an existing one) in
    blocks of ``block`` samples, each flushed, as a driver streaming from the robot would."""
    total = sum(r.n_samples for r in records)
    done = 0
    with (open_experiment(path, "a") if append else create_experiment(path, overwrite=True)) as exp:
        if not append:
            exp.set_metadata(subject="virtual", site="forearm (virtual lab)", operator="skinkit demo")
        for record in records:
            with exp.record_writer(record.protocol, record.channels, record.rate_hz) as w:
                for start in range(0, record.n_samples, block):
                    chunk = record.slice(start, start + block)
                    w.append(chunk)
                    done += chunk.n_samples
                    progress("stream to store", done / total)


def run_protocols(path: Path, protocols: list[str], driver: str = "sim", progress: bool = False,
                  **connect: Any) -> list[dict[str, Any]]:
    """Connect the ``driver`` plugin (``connect`` options), home it, run each named protocol
    of :mod:`skinkit.acquisition` into experiment ``path``, disconnect. Returns, per protocol,
    samples written and lost, the tip's peak-to-peak travel [m] and peak normal force [N]."""
    from skinkit.acquisition import make_protocol, run_protocol

    drv = registry.create("skinkit.drivers", driver)
    out = []
    drv.connect(**connect)
    try:
        drv.home()
        for name in protocols:
            with open_experiment(path, "a") as exp:
                s = run_protocol(drv, make_protocol(name), exp, progress=progress)
            with open_experiment(path) as exp:
                rec = exp.read_record(name)
            travel = np.ptp(rec.tip_position, axis=0)
            out.append({"protocol": name, "samples": s.samples, "lost": s.lost, "fault": s.fault,
                        "simulated_s": s.duration_s, "wall_s": s.wall_s,
                        "tip_travel_pp_m": [float(v) for v in travel],
                        "peak_normal_force_N": float(np.max(np.abs(rec.tip_force[:, 2])))})
    finally:
        drv.disconnect()
    return out
