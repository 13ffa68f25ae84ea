"""``skinkit bench store``: the cost of crash-safe appending, against plain h5py on the same blocks.

skinkit appends in SWMR mode and advances a committed-length marker after each flushed
block; the peer appends the same blocks to a plain chunked h5py file and flushes per block
(what one would write by hand, without the ordering guarantee).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from skinkit.schemas import Protocol, RobotRecord
from skinkit.store import create_experiment

CHANNELS = ["motor_position", "motor_current", "motor_force", "tip_position", "tip_force", "tip_torque"]


def _blocks(n_blocks: int, block: int, rng: np.random.Generator) -> list[RobotRecord]:
    out = []
    for k in range(n_blocks):
        t = (np.arange(block) + k * block) / 10_000.0
        out.append(RobotRecord(time_s=t, **{c: rng.normal(size=(block, 3)) for c in CHANNELS}))
    return out


def run(n_blocks: int = 200, block: int = 1000, repeats: int = 3) -> dict[str, float]:
    """Time both writers on the same blocks; best of ``repeats``. Returns samples/s and ratio."""
    blocks = _blocks(n_blocks, block, np.random.default_rng(0))
    n = n_blocks * block
    best_sk = best_h5 = np.inf
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(repeats):
            path = Path(tmp) / f"sk{r}.h5"
            t0 = time.perf_counter()
            with create_experiment(path) as exp:
                with exp.record_writer(Protocol("bench"), CHANNELS, 10_000.0, chunk=block) as w:
                    for b in blocks:
                        w.append(b)
            best_sk = min(best_sk, time.perf_counter() - t0)

            path = Path(tmp) / f"h5{r}.h5"
            t0 = time.perf_counter()
            with h5py.File(path, "w") as f:
                ds = {c: f.create_dataset(c, (0, 3), maxshape=(None, 3), chunks=(block, 3), dtype="f8")
                      for c in CHANNELS}
                ds["time_s"] = f.create_dataset("time_s", (0,), maxshape=(None,), chunks=(block,), dtype="f8")
                ds["flags"] = f.create_dataset("flags", (0,), maxshape=(None,), chunks=(block,), dtype="u4")
                m = 0
                for b in blocks:
                    for name, d in ds.items():
                        d.resize(m + block, axis=0)
                        d[m:] = getattr(b, name)
                    m += block
                    f.flush()
            best_h5 = min(best_h5, time.perf_counter() - t0)
    return {"samples": n, "block": block, "channels": len(CHANNELS),
            "skinkit_samples_per_s": n / best_sk, "h5py_samples_per_s": n / best_h5,
            "ratio_skinkit_over_h5py": best_h5 / best_sk}


def summary_lines(res: dict[str, float]) -> list[str]:
    """The figures of :func:`run` as lines of text."""
    return [f"{res['samples']} samples x {res['channels']} channels in blocks of {res['block']}:",
            f"  skinkit (SWMR, committed marker): {res['skinkit_samples_per_s']:,.0f} samples/s",
            f"  plain h5py, flush per block:      {res['h5py_samples_per_s']:,.0f} samples/s",
            f"  ratio skinkit/h5py throughput:    {res['ratio_skinkit_over_h5py']:.2f}"]
