"""The calibrations: the camera rig (intrinsics, distortion, where each camera sits and looks) with
the reprojection errors a calibration stored, and the device calibrations of ``/calibrations``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from skinkit.report.common import (
    Section,
    e,
    figure,
    img,
    mpl,
    note,
    num,
    plural,
    png_uri,
    slug,
    t,
    table,
    value_text,
)
from skinkit.schemas import CameraRig
from skinkit.store.experiment import Experiment


def _centres(rig: CameraRig) -> tuple[np.ndarray, np.ndarray]:
    """Camera centres ``(C, 3)`` [m] and optical axes ``(C, 3)`` (unit) in the world frame."""
    R = np.array([c.R for c in rig.cameras], float)
    tt = np.array([c.t for c in rig.cameras], float)
    centres = -np.einsum("cji,cj->ci", R, tt)   # C = -Rᵀ t
    axes = R[:, 2, :]                           # Rᵀ e_z: the camera's z axis in the world
    return centres, axes


def _rig_figure(rig: CameraRig) -> str:
    """Camera centres and optical axes in three orthogonal views of the world frame [mm]."""
    c, a = _centres(rig)
    c_mm = c * 1e3
    span = float(np.linalg.norm(c_mm, axis=1).max()) or 1.0
    arrow = 0.35 * span
    fig = figure(10.0, 3.6)
    for k, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
        ax = fig.add_subplot(1, 3, k + 1)
        ax.plot([0], [0], "k+", ms=10)
        for n, cam in enumerate(rig.cameras):
            ax.annotate("", xy=(c_mm[n, i] + arrow * a[n, i], c_mm[n, j] + arrow * a[n, j]),
                        xytext=(c_mm[n, i], c_mm[n, j]), arrowprops={"arrowstyle": "->", "color": f"C{n}"})
            ax.plot(c_mm[n, i], c_mm[n, j], "o", color=f"C{n}", label=mpl(cam.name))
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel(f"{'xyz'[i]} [mm]", fontsize=8)
        ax.set_ylabel(f"{'xyz'[j]} [mm]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    fig.axes[0].legend(fontsize=7)
    fig.suptitle("camera centres (dots) and optical axes (arrows); + the world origin", fontsize=9)
    return png_uri(fig)


def _rig_table(rig: CameraRig) -> str:
    c, a = _centres(rig)
    rows = []
    for n, cam in enumerate(rig.cameras):
        K = np.asarray(cam.K, float)
        dist = ", ".join(num(x, 3) for x in np.asarray(cam.distortion, float)) or "none"
        rows.append([t(cam.name, cam.name), t("×".join(str(int(s)) for s in cam.image_size)),
                     t(num(K[0, 0], 6), float(K[0, 0])), t(num(K[1, 1], 6), float(K[1, 1])),
                     t(f"{num(K[0, 2], 5)}, {num(K[1, 2], 5)}"), t(dist),
                     t(", ".join(num(x, 4) for x in c[n] * 1e3)), t(", ".join(num(x, 3) for x in a[n])),
                     t(num(np.linalg.norm(c[n]) * 1e3, 4), float(np.linalg.norm(c[n])))])
    return table(["camera", "image [px]", "fx [px]", "fy [px]", "principal point [px]", "distortion",
                  "centre [mm]", "optical axis", "distance to origin [mm]"], rows)


def _flatten(d: Mapping[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping) and v and prefix.count(".") < 2:
            out.extend(_flatten(v, key + "."))
        else:
            out.append((key, v))
    return out


def _is_reprojection(key: str) -> bool:
    k = key.lower()
    return "reproj" in k or k.endswith("rms_px") or "rms_px" in k


def _reprojection(cals: dict[str, dict[str, Any]], rig: CameraRig | None) -> str:
    """The reprojection errors any calibration stored: per camera when a value is a list as long
    as the rig, else as they are."""
    rows = []
    for name, d in cals.items():
        for key, v in _flatten(d):
            if not _is_reprojection(key):
                continue
            if rig is not None and isinstance(v, list) and len(v) == len(rig.cameras):
                for cam, x in zip(rig.cameras, v, strict=True):
                    key_x = x if isinstance(x, float) else None
                    rows.append([t(name), t(key), t(cam.name), t(value_text(x), key_x)])
            else:
                rows.append([t(name), t(key), t("all"), t(value_text(v))])
    if not rows:
        return note("The file stores no reprojection error: the rig was written without the calibration's "
                    "residuals (recalibrate with skinkit vision calibrate to see them printed).")
    return table(["calibration", "quantity", "camera", "value"], rows)


def _overall_rms(cals: dict[str, dict[str, Any]]) -> float | None:
    """The first overall reprojection RMS [px] a calibration stored (a number, not per camera)."""
    for d in cals.values():
        for key, v in _flatten(d):
            if _is_reprojection(key) and "per_" not in key and isinstance(v, (int, float)) \
                    and not isinstance(v, bool):
                return float(v)
    return None


def _calibration(name: str, d: dict[str, Any]) -> str:
    rows = []
    for key, v in _flatten(d):
        rows.append([t(key, key), t(value_text(v))])
    body = table(["quantity", "value"], rows, sortable=False) if rows else note("(empty)")
    return f'<div class="item" id="calibration-{slug(name)}"><h4>{e(name)}</h4>{body}</div>'


def section(exp: Experiment) -> Section:
    """The camera rig (``/rig``) and the device calibrations (``/calibrations``)."""
    rig = exp.read_rig() if exp.camera_names() else None
    cals = {n: exp.read_calibration(n) for n in exp.calibration_names()}
    if rig is None and not cals:
        return Section("calibration", "Calibration", None,
                       "omitted: the file holds no camera rig and no device calibration")
    body, what = "", []
    if rig is not None:
        body += ("<h3>Camera rig</h3><p>World → camera: x_cam = R x + t; the centre is −Rᵀt. Pixel "
                 "quantities as calibrated; distortion coefficients in OpenCV's order.</p>")
        body += _rig_table(rig) + img(_rig_figure(rig), "where the cameras sit and look")
        body += "<h4>Reprojection errors</h4>" + _reprojection(cals, rig)
        overall = _overall_rms(cals)
        what.append(plural(len(rig.cameras), "camera")
                    + ("" if overall is None else f", reprojection RMS {num(overall, 3)} px"))
    if cals:
        body += "<h3>Calibrations stored</h3>" + "".join(_calibration(n, d) for n, d in cals.items())
        what.append(plural(len(cals), "calibration") + f" ({', '.join(cals)})")
    return Section("calibration", "Calibration", body, ", ".join(what))
