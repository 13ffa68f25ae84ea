"""The chain's closing comparison: what each step measured against the virtual lab's truth,
read only after every step has finished (the session file and the truth kept beside it)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.store import open_experiment

#: the chain's output files: the session and, apart from it, the truth
SESSION = "session.h5"
TRUTH = "truth.json"


def _truth_field(out: Path) -> Any:
    return np.load(out / "truth-surface.npz")


def _profile_error(out: Path, curved: bool) -> float:
    """RMS [m] of the measured profile's height against the true skin at rest (pre-stressed)."""
    from skinkit.lab.imaging import displacement_field
    from skinkit.lab.session import surface_height

    field = _truth_field(out)
    rest = next(k for k in field.files if k.startswith("followed_"))
    u0 = displacement_field(field["grid_m"], field["points_m"], field[rest][:, 0] - field["points_m"])
    with open_experiment(out / SESSION) as exp:
        p = exp.read_profile("undeformed").points
    X = p[:, :2] - u0(p[:, 0], p[:, 1])[:, :2]   # material coordinates (one fixed-point step: u0 is small)
    z = surface_height(X, curved) + u0(X[:, 0], X[:, 1])[:, 2]
    return float(np.sqrt(np.mean((p[:, 2] - z) ** 2)))


def _truth_motion(field: Any, key: str, ref: np.ndarray, window_m: float | None, f: int) -> np.ndarray:
    """``(n, 3)`` [m] the truth's displacement of frame ``f`` from its first frame at ``ref``
    ``(n, 3)`` [m], averaged over a subset's footprint ``window_m`` [m] (None: at the point)."""
    from skinkit.forward.fe import window_offsets, window_weights
    from skinkit.lab.imaging import displacement_field

    off, wq = (window_offsets(window_m), window_weights()) if window_m else (np.zeros((1, 3)), np.ones(1))
    u = displacement_field(field["grid_m"], field["points_m"], field[key][:, f] - field[key][:, 0])
    return sum(wq[q] * u(ref[:, 0] + off[q, 0], ref[:, 1] + off[q, 1]) for q in range(len(wq)))


def tracked_against_truth(out: Path, windowed: bool) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per track of ``out``'s session: every valid tracked displacement ``(n, 3)`` [m] from the
    protocol's start (its rest state) and the truth's ``(n, 3)`` [m] at the tracked point or
    (``windowed``) averaged over the subset's footprint, as the forward model predicts it."""
    field = _truth_field(out)
    pairs: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    with open_experiment(out / SESSION) as exp:
        for name in exp.track_names():
            key = f"followed_{name}"
            if key not in field.files:
                continue
            tr = exp.read_track(name)
            w = exp.track_attrs(name).get("window_m") if windowed else None
            ref = tr.points[:, 0]
            meas, true = [], []
            for f in range(1, tr.time_s.size):
                pred = _truth_motion(field, key, ref, w, f)
                ok = tr.valid[:, f]
                meas.append(tr.points[ok, f] - ref[ok])
                true.append(pred[ok])
            pairs[name] = (np.concatenate(meas), np.concatenate(true))
    return pairs


def track_error_z(out: Path) -> float | None:
    """RMS over every valid tracked displacement and axis of its error against the truth's subset
    mean, over the standard error the track states for it (√(σ₀² + σ_f²): the reference frame's
    and the frame's); ≈ 1 when the stated errors are honest; None without stated errors."""
    field = _truth_field(out)
    zs = []
    with open_experiment(out / SESSION) as exp:
        for name in exp.track_names():
            key = f"followed_{name}"
            tr = exp.read_track(name)
            if key not in field.files or tr.uncertainty_m is None:
                continue
            w = exp.track_attrs(name).get("window_m")
            ref, s0 = tr.points[:, 0], tr.uncertainty_m[:, 0]
            for f in range(1, tr.time_s.size):
                pred = _truth_motion(field, key, ref, w, f)
                ok = tr.valid[:, f] & tr.valid[:, 0]
                sd = np.sqrt(s0[ok] ** 2 + tr.uncertainty_m[ok, f] ** 2)
                zs.append(((tr.points[ok, f] - ref[ok] - pred[ok]) / sd).ravel())
    if not zs:
        return None
    z = np.concatenate(zs)
    return float(np.sqrt(np.mean(z**2)))


def _track_error(out: Path, windowed: bool) -> float | None:
    """RMS [m] of the 3D error of every tracked displacement against the truth's surface motion,
    at the tracked point or (``windowed``) averaged over its subset's footprint."""
    pairs = tracked_against_truth(out, windowed)
    if not pairs:
        return None
    e = np.concatenate([m - t for m, t in pairs.values()])
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


def compare(out: Path, summary: dict[str, Any]) -> list[dict[str, Any]]:
    """Step 7: the closing table — each step's result against the truth file (read only here)."""
    from skinkit.lab.forearm import canonical_prestress

    truth = json.loads((out / TRUTH).read_text())
    rows: list[dict[str, Any]] = []

    def row(step: str, what: str, found: float | str | None, true: float | str | None, unit: str = "",
            rel: bool = True, se: float | None = None) -> None:
        err = None
        if isinstance(found, (int, float)) and isinstance(true, (int, float)) and (true != 0 or not rel):
            err = 100.0 * (found / true - 1.0) if rel else found - true
        inside = None if se is None or err is None else bool(abs(found - true) <= 1.96 * se)
        rows.append({"step": step, "result": what, "found": found, "truth": true, "unit": unit,
                     "error": err, "error_unit": "%" if rel else unit, "time_s": None,
                     "se": se, "within_95": inside})

    lt, lin, wie = truth["lumped"], summary["lumped"]["linear"], summary["lumped"]["wiener"]
    row("lumped", "K", lin["K_N_per_m"], lt["K_N_per_m"], "N/m")
    row("lumped", "B", lin["B_Ns_per_m"], lt["B_Ns_per_m"], "N s/m")
    row("lumped", "I", lin["I_kg"], lt["I_kg"], "kg")
    row("lumped", "Wiener C1", wie["C1_m"], lt["C1_m"], "m")
    row("lumped", "Wiener C2", wie["C2_per_N"], lt["C2_per_N"], "1/N")
    cams = summary["cameras"]
    row("cameras", "reprojection RMS", cams["reprojection_rms_px"], None, "px")
    um = 1e6
    curved = bool(truth["surface"]["curved"])
    row("cameras", "profile height RMS error", um * _profile_error(out, curved), 0.0, "µm", rel=False)
    for windowed, what in ((False, "point motion"), (True, "subset mean")):
        e = _track_error(out, windowed)
        row("cameras", f"track RMS error vs {what}", None if e is None else um * e, 0.0, "µm", rel=False)
    z = track_error_z(out)
    if z is not None:   # the tracks' stated standard errors against their errors (≈ 1: honest)
        row("cameras", "track error over its standard error (RMS)", z, 1.0, "1", rel=False)
    mesh = truth.get("mesh") or {}
    if mesh:   # the truth's mesh is its own: the model's discretisation error is in the data
        row("acquire", f"truth mesh ({mesh['mode']}) unknowns", mesh["truth_unknowns"], None)
        row("acquire", "model mesh unknowns", mesh["model_unknowns"], None)
        # the truth is itself a discretised solution: its own error (the lab's estimate) is part
        # of what separates the fitted parameters from the truth's, beside the model's
        for ch, d in (mesh.get("discretisation") or {}).items():
            row("acquire", f"truth mesh error {ch} (×σ)", d["truth_over_noise"], None, "1")
            row("acquire", f"model mesh error {ch} (×σ)", d["model_over_noise"], None, "1")
    tp = {p["name"]: p["value"] for p in truth["parameters"]}
    fe = summary["identify"]
    for name, par in fe["parameters"].items():
        if name in tp and par.get("free"):
            row("identify", name, par["value"], tp[name], par.get("unit", ""))
    gap = summary["diagnose"]
    named = gap.get("named") or []
    row("diagnose", "named effect", ", ".join(named) or "none", "prestress", rel=False)
    cand = next((c for c in gap.get("candidates", [])
                 if c["effect"] == "prestress" and c.get("parameters")), None)
    if cand is not None:
        p = {k.split(".", 1)[1]: v["value"] for k, v in cand["parameters"].items()}
        l1, l2, a = canonical_prestress(p["l1"], p["l2"], p["angle"])
        eff = next(e for e in truth["effects"] if e["name"] == "prestress")
        t1, t2, ta = canonical_prestress(eff["l1"], eff["l2"], eff["angle"])
        row("diagnose", "prestress λ1", l1, t1, "1")
        row("diagnose", "prestress λ2", l2, t2, "1")
        row("diagnose", "prestress angle", math.degrees(a), math.degrees(ta), "deg", rel=False)
    row("diagnose", "shrinkage of the excess", gap["shrinkage"]["overall"], None, "1")
    final, final_se = gap.get("final_parameters") or {}, gap.get("final_se") or {}
    if named:   # the model with the named effect: its parameters against the truth
        for name, par in fe["parameters"].items():
            if name in tp and par.get("free") and name in final:
                row("diagnose", f"{name} (with {named[0]})", final[name], tp[name], par.get("unit", ""),
                    se=final_se.get(name))
    return rows
