"""Acquisition step: run named protocols through a driver plugin into an experiment file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from skinkit import registry
from skinkit.store import open_experiment


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
