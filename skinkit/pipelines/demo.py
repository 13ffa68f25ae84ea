"""The main job on the embedded default: a virtual-lab session run through every step that exists.

Steps: simulate a stochastic-force session on a lumped skin whose truth is known, stream it
block by block into an experiment file, read it back validated, plot it, and summarise.
Later steps (identification, vision, finite elements, gap diagnosis) extend this pipeline.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.lab.lumped import LumpedSkin, simulate
from skinkit.schemas import RobotRecord
from skinkit.store import create_experiment, open_experiment

Progress = Callable[[str, float], None]


def _quiet(step: str, fraction: float) -> None:
    pass


def stream_record(path: Path, record: RobotRecord, block: int, progress: Progress = _quiet) -> None:
    """Write ``record`` into a new experiment file ``path`` in blocks of ``block`` samples,
    each flushed, as a driver streaming from the robot would."""
    with create_experiment(path, overwrite=True) as exp:
        exp.set_metadata(subject="virtual", site="forearm (virtual lab)", operator="skinkit demo")
        with exp.record_writer(record.protocol, record.channels, record.rate_hz) as w:
            for start in range(0, record.n_samples, block):
                w.append(record.slice(start, start + block))
                progress("stream to store", min(1.0, (start + block) / record.n_samples))


def plot_record(record: RobotRecord, path: Path) -> Path:
    """Force and position against time, and the position spectrum; saved as PNG at ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy import signal

    fig, axes = plt.subplots(3, 1, figsize=(8, 7), constrained_layout=True)
    t = record.time_s
    axes[0].plot(t, record.tip_force[:, 2], lw=0.5)
    axes[0].set_ylabel("tip force z [N]")
    axes[1].plot(t, record.tip_position[:, 2] * 1e3, lw=0.5, color="C1")
    axes[1].set_ylabel("tip position z [mm]")
    axes[1].set_xlabel("time [s]")
    fx, pf = signal.welch(record.tip_force[:, 2], fs=record.rate_hz, nperseg=1024)
    _, pxy = signal.csd(record.tip_force[:, 2], record.tip_position[:, 2], fs=record.rate_hz, nperseg=1024)
    # Above the input's band the ratio is noise over noise: show only excited frequencies.
    band = (fx > 0) & (pf > 1e-3 * pf.max())
    axes[2].loglog(fx[band], np.abs(pxy[band] / pf[band]) * 1e3)
    axes[2].set_xlabel("frequency [Hz]")
    axes[2].set_ylabel("|compliance| [mm/N]")
    fig.suptitle(f"{record.protocol.name}: {record.n_samples} samples at {record.rate_hz:.0f} Hz")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def run_demo(out_dir: str | Path, seed: int = 0, progress: Progress = _quiet) -> dict[str, Any]:
    """Run the demo pipeline into ``out_dir``; returns the JSON-ready summary (also written to
    ``out_dir/summary.json``)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    truth = LumpedSkin()
    progress("simulate virtual session", 0.0)
    record = simulate(truth, seed=seed)
    progress("simulate virtual session", 1.0)
    session = out / "session.h5"
    stream_record(session, record, block=1000, progress=progress)
    with open_experiment(session) as exp:
        summary_store = exp.summary()
        back = exp.read_record(record.protocol.name)
    progress("read back and validate", 1.0)
    if not np.array_equal(back.tip_position, record.tip_position):
        raise RuntimeError("the experiment file did not return what was written")
    plot = plot_record(back, out / "record.png")
    progress("plot", 1.0)
    summary = {"truth": asdict(truth), "experiment_file": str(session), "store": summary_store,
               "plots": [str(plot)]}
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary
