"""The main job on the embedded default: a virtual-lab session run through every step that exists.

1. simulate two stochastic-force protocols on lumped skins whose truth is known (thesis
   Table 7 forearm behind the robot's 25 g; the same followed by the Table 8 nonlinearity);
2. stream them block by block into an experiment file, as a driver would, and read them back;
3. identify the linear model (K, B, I, robot mass removed) on the first and the Wiener model
   (C1, C2, Is, Bs) on the second, store both as fit results, compare them with the truth;
4. plot the record and the identification (thesis Fig. 4-12 style);
5. run thesis Table 12's normal indentation (1.5 mm peak to peak, 0.1 Hz, three periods)
   through the simulated robot (the ``sim`` driver plugin: voice coils, PID, sensor noise,
   safety limits, a Kelvin–Voigt skin) into the same file;
6. solve the layered in vivo finite-element model under a 20 mN tip force, with and without
   the skin's natural pre-stretch (needs the law plugins), writing a ParaView series;
7. render the stereoscope's views of calibration boards and of the speckled forearm,
   undeformed and indented; calibrate the rig, profile the surface automatically, track it
   in 3D, and compare with the rendered truth (needs the tracker and profiler plugins).

Later steps (finite elements, identification of FE parameters, gap diagnosis) extend this
pipeline.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.lab.lumped import LumpedTruth, stochastic_session
from skinkit.schemas import FitResult, Parameter, ParameterSet, RobotRecord
from skinkit.store import create_experiment, open_experiment

Progress = Callable[[str, float], None]


def _quiet(step: str, fraction: float) -> None:
    pass


def stream_records(path: Path, records: list[RobotRecord], block: int,
                   progress: Progress = _quiet, append: bool = False) -> None:
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


def plot_record(record: RobotRecord, path: Path) -> Path:
    """Force and position against time, and the force-to-position compliance; PNG at ``path``."""
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
    f = record.tip_force[:, 2] - record.tip_force[:, 2].mean()
    fx, pf = signal.welch(f, fs=record.rate_hz, nperseg=1024)
    _, pxy = signal.csd(f, record.tip_position[:, 2], fs=record.rate_hz, nperseg=1024)
    # Above the input's band the ratio is noise over noise: show only excited frequencies.
    band = (fx > 0) & (pf > 1e-3 * pf.max())
    axes[2].loglog(fx[band], np.abs(pxy[band] / pf[band]) * 1e3)
    axes[2].set_xlabel("frequency [Hz]")
    axes[2].set_ylabel("|compliance| [mm/N]")
    fig.suptitle(f"{record.protocol.name}: {record.n_samples} samples at {record.rate_hz:.0f} Hz")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _fit(model: str, values: dict[str, tuple[float, str, float]], vaf_pct: float,
         n_samples: int) -> FitResult:
    """A FitResult from name -> (value, unit, standard error)."""
    params = ParameterSet(Parameter(k, v, u, lower=-math.inf) for k, (v, u, _) in values.items())
    se = [s for (_, _, s) in values.values()]
    cov = np.diag(np.square(se)) if all(np.isfinite(se)) else None
    return FitResult(model, params, objective=1.0 - vaf_pct / 100.0, n_evaluations=n_samples,
                     covariance=cov, extra={"vaf_pct": vaf_pct},
                     message="objective = 1 - VAF/100 (fraction of output variance unexplained)")


def run_demo(out_dir: str | Path, seed: int = 0, progress: Progress = _quiet) -> dict[str, Any]:
    """Run the demo pipeline into ``out_dir``; returns the JSON-ready summary (also written to
    ``out_dir/summary.json``)."""
    from skinkit.sysid import identify_linear, identify_wiener
    from skinkit.sysid.plots import plot_identification

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    truth = LumpedTruth()
    progress("simulate virtual session", 0.0)
    records = [stochastic_session(truth, wiener=False, seed=seed),
               stochastic_session(truth, wiener=True, seed=seed + 1)]
    progress("simulate virtual session", 1.0)
    session = out / "session.h5"
    stream_records(session, records, block=1000, progress=progress)
    with open_experiment(session) as exp:
        lin_rec, wie_rec = (exp.read_record(r.protocol.name) for r in records)
    progress("read back and validate", 1.0)
    for a, b in zip((lin_rec, wie_rec), records, strict=True):
        if not np.array_equal(a.tip_position, b.tip_position):
            raise RuntimeError("the experiment file did not return what was written")

    progress("identify linear + Wiener", 0.0)
    lin = identify_linear(lin_rec, robot=truth.robot)
    progress("identify linear + Wiener", 0.5)
    wie = identify_wiener(wie_rec)
    progress("identify linear + Wiener", 1.0)
    ld, wd = lin.to_dict(), wie.to_dict()
    with open_experiment(session, "a") as exp:
        exp.write_fit("linear", _fit("linear", {
            "K": (ld["K_N_per_m"], "N/m", ld["K_se_N_per_m"]),
            "B": (ld["B_Ns_per_m"], "N s/m", ld["B_se_Ns_per_m"]),
            "I": (ld["I_kg"], "kg", ld["I_se_kg"])}, ld["vaf_linear_pct"], lin_rec.n_samples))
        exp.write_fit("wiener", _fit("wiener", {
            "C1": (wd["C1_m"], "m", wd["C1_se_m"]), "C2": (wd["C2_per_N"], "1", wd["C2_se_per_N"]),
            "Is": (wd["Is_s2"], "1", wd["Is_se_s2"]), "Bs": (wd["Bs_s"], "s", wd["Bs_se_s"])},
            wd["vaf_wiener_pct"], wie_rec.n_samples))
        summary_store = exp.summary()

    plots = [plot_record(wie_rec, out / "record.png"),
             plot_identification(lin, lin_rec.tip_force[:, 2], lin_rec.tip_position[:, 2],
                                 out / "linear.png"),
             plot_identification(wie, wie_rec.tip_force[:, 2], wie_rec.tip_position[:, 2],
                                 out / "wiener.png")]
    progress("plot", 1.0)

    def err(est: float, true: float) -> float:
        return 100.0 * (est / true - 1.0)

    # The Wiener model's Is and Bs describe the whole moving system, robot included.
    i_total = truth.I_kg + truth.robot_mass_kg
    summary = {
        "truth": truth.to_dict(),
        "experiment_file": str(session),
        "store": summary_store,
        "linear": {"K_N_per_m": ld["K_N_per_m"], "B_Ns_per_m": ld["B_Ns_per_m"], "I_kg": ld["I_kg"],
                   "vaf_linear_pct": ld["vaf_linear_pct"], "warnings": ld["warnings"]},
        "linear_error_pct": {"K": err(ld["K_N_per_m"], truth.K_N_per_m),
                             "B": err(ld["B_Ns_per_m"], truth.B_Ns_per_m),
                             "I": err(ld["I_kg"], truth.I_kg)},
        "wiener": {"C1_m": wd["C1_m"], "C2_per_N": wd["C2_per_N"], "Is_s2": wd["Is_s2"],
                   "Bs_s": wd["Bs_s"], "vaf_wiener_pct": wd["vaf_wiener_pct"],
                   "vaf_linear_pct": wd["vaf_linear_pct"], "warnings": wd["warnings"]},
        "wiener_error_pct": {"C1": err(wd["C1_m"], truth.C1_m), "C2": err(wd["C2_per_N"], truth.C2_per_N),
                             "Is": err(wd["Is_s2"], i_total / truth.K_N_per_m),
                             "Bs": err(wd["Bs_s"], truth.B_Ns_per_m / truth.K_N_per_m)},
        "plots": [str(p) for p in plots],
    }
    summary["robot"] = run_robot(session, seed, progress)
    summary["fem"] = run_fem(out, progress)
    summary["vision"] = run_vision(session, out, seed, progress)
    with open_experiment(session) as exp:
        summary["store"] = exp.summary()
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    return summary


def run_robot(session: Path, seed: int, progress: Progress) -> dict[str, Any]:
    """Acquisition step through the simulated robot, if a ``sim`` driver is installed."""
    from skinkit import registry
    from skinkit.pipelines.acquire import run_protocols

    if "sim" not in registry.names("skinkit.drivers"):
        return {"skipped": "needs the driver plugin skinkit.drivers:sim (skinkit-hardware)"}
    progress("robot: normal indentation", 0.0)
    (res,) = run_protocols(session, ["normal_indentation"], "sim", skin="kelvin-voigt", seed=seed)
    progress("robot: normal indentation", 1.0)
    return res


def run_fem(out: Path, progress: Progress) -> dict[str, Any]:
    """The in vivo model indented under force control, with and without pre-stretch."""
    from skinkit import registry
    from skinkit.lab.invivo import LAWS, static_force_spec

    missing = [law for law in LAWS if law not in registry.names("skinkit.laws")]
    if missing:
        return {"skipped": f"needs law plugins not installed: {', '.join(missing)}"}
    from skinkit.fem.model import build_model
    from skinkit.fem.run import solve_model, write_outputs

    res: dict[str, Any] = {}
    for k, prestretch in enumerate((True, False)):
        progress("FE: in vivo indentation", k / 2)
        model = build_model(static_force_spec(prestretch))
        sol, info = solve_model(model)
        files = write_outputs(model, sol, info, out / "fem" / model.name)
        last = info["steps"][-1]
        res["with_prestretch" if prestretch else "without_prestretch"] = {
            "dof": info.get("dof"), "tip_displacement_m": last["tip_displacement_m"],
            "tip_force_N": last["tip_force_N"],
            "newton_iterations": info["newton_iterations"],  # the FE summary's count, not a recount
            "wall_s": info.get("wall_s"), "paraview": files.get("vtu")}
    progress("FE: in vivo indentation", 1.0)
    return res


def run_vision(session: Path, out: Path, seed: int, progress: Progress) -> dict[str, Any]:
    """Stereo step on a rendered session; errors against the truth in micrometres."""
    from skinkit.pipelines.stereo import calibrate_profile_track, missing_plugins

    missing = missing_plugins()
    if missing:
        return {"skipped": f"needs plugins not installed: {', '.join(missing)}"}
    from skinkit.lab.stereo import BOARD_INNER, BOARD_SQUARE_M, stereo_session
    from skinkit.vision.plots import plot_profile

    progress("render stereo views", 0.0)
    lab = stereo_session(seed)
    progress("render stereo views", 1.0)
    res, profile, track = calibrate_profile_track(session, lab.boards, lab.skin, BOARD_INNER,
                                                  BOARD_SQUARE_M, progress=progress)
    P = lab.from_calibrated(profile.points)
    dz = P[:, 2] - lab.true_height_m(P)
    ok = track.valid[:, 1]
    e = np.linalg.norm(lab.from_calibrated(track.points[ok, 1]) - lab.true_indented(P[ok]), axis=1)
    res["profile_error_um"] = {"rms": float(1e6 * np.sqrt(np.mean(dz**2))),
                               "max": float(1e6 * np.abs(dz).max())}
    res["track_error_um"] = {"rms": float(1e6 * np.sqrt(np.mean(e**2))), "max": float(1e6 * e.max())}
    res["plots"] = [str(plot_profile(profile, out / "profile.png", title="automatic profile"))]
    return res
