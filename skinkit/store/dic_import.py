"""Import of a two-pad extensometer record with 2D image tracking (``skinkit import-extensometer``).

The folder layout is that of ``aflahelouneg/inverse_identification_soft_tissue`` (see
``docs/guide/real-records.md``): ``reactionforce/u_moving_pad.dat`` and ``f_moving_pad.dat`` (one value
a line: device displacement [mm] and force [N], no time stamps) and ``displacement/``
``x0.dat``, ``y0.dat`` (``(P,)`` tracked points in the reference image [px]), ``xt.dat``,
``yt.dat`` (``(P, F)``: the same points in the ``F`` later images [px]) and
``x0_ref_k.dat`` ... ``yt_ref_k.dat`` (``(2,)`` and ``(2, F)``: two marks on pad ``k``'s
holder). The folder given may be the record's root (holding ``datafiles_unprocessed/``) or
the ``datafiles_unprocessed`` folder itself.

What the import does, in order (numbers for the healthy record in ``docs/guide/real-records.md``):

1. **Pixel scale** [m/px] = ``mark_spacing`` (the known distance between the two marks of one
   pad, 24 mm for this extensometer) / the mean over both pads of the distance between its
   two marks in the reference image.
2. **Skin frame**: origin midway between the two pads' centres (centre = mean of its two
   marks) in the reference image; x from the fixed to the moving pad's centre; the camera
   looks into the skin with image y down, so y = z x x with z out of the skin, i.e. the
   in-plane unit vectors in image coordinates are ``ex`` and ``(ex_y, -ex_x)``. Each later
   image is first translated so that the fixed pad's centre stays where it was in the
   reference image (the camera moves relative to the fixed pad), then mapped the same way.
3. **Moving-pad displacement seen in the images**, ``d_k`` [m] along x, and the **frame
   times**: the device has no clock, so force sample ``i`` is given the nominal time
   ``i / rate_hz``; the reference image is matched to the device's reading at rest (its
   minimum before the extension starts, ``u_rest``) and image ``k`` to the (fractional)
   sample at which the device displacement, in the monotonic part of the record, first
   reaches ``u_rest + d_k``. The residual mismatch is reported as the scatter of those
   times about a straight line in frame index (a camera at a constant rate).
4. **Validity**: a point is invalid in a frame where its coordinates are not finite, or where
   its displacement differs from the median displacement of its 8 nearest neighbours by
   more than 8 robust standard deviations (per axis, over all points and frames).
5. **Noise** [m] per in-plane axis: the scatter of the valid positions of each point about a
   cubic in frame index (1.4826 MAD over all points and frames, times sqrt(F / (F - 4)) for
   the fitted coefficients).

The robot record holds the device's raw values: ``tip_position`` x = displacement of the
moving pad [m] (+x when pulling), ``tip_force`` x = force the moving pad applies to the skin
[N] (+x when pulling); y and z are NaN. Outliers in the force are kept and not flagged.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.errors import SchemaError, StoreError
from skinkit.schemas import Protocol, RobotRecord, SurfaceTrack

#: distance between the two marks on one pad's holder [m] (the extensometer's window width)
MARK_SPACING_M = 0.024
#: nominal sampling rate given to the device's samples [Hz] (the files have no time stamps)
NOMINAL_RATE_HZ = 10.0
_MAD = 1.4826
_OUTLIER_SIGMAS = 8.0
_NEIGHBOURS = 8
_POLY_DEGREE = 3


@dataclass
class ExtensometerImport:
    """What :func:`read_extensometer` made of a record folder.

    Attributes:
        record: the device's samples as a :class:`RobotRecord` (x only; nominal times).
        track: the tracked points, ``(P, F, 3)`` [m] in the skin frame with z = 0.
        record_attrs: facts attached to the record (JSON-ready).
        track_attrs: facts attached to the track (``dimensions = 2``, ``noise_m``, ...).
    """

    record: RobotRecord
    track: SurfaceTrack
    record_attrs: dict[str, Any] = field(default_factory=dict)
    track_attrs: dict[str, Any] = field(default_factory=dict)


def _load(path: Path, ndim: int) -> np.ndarray:
    """A whitespace-separated numeric table as a ``ndim``-dimensional float array."""
    p = str(path)
    if not path.is_file():
        raise StoreError(p, "", "no such file")
    try:
        a = np.loadtxt(path, dtype=float, ndmin=2)
    except (ValueError, UnicodeDecodeError) as exc:
        raise StoreError(p, "", f"is not a numeric table ({str(exc).splitlines()[0][:80]})") from None
    if a.size == 0:
        raise StoreError(p, "", "is empty")
    if ndim == 1:
        if min(a.shape) != 1:
            raise StoreError(p, "", f"expected one column of values, got shape {a.shape}")
        return a.ravel()
    return a


def _not_finite_at(path: Path, a: np.ndarray) -> None:
    """Refuse the first value of ``a`` (as :func:`_load` read ``path``) that is not finite,
    naming the file, its line (blank and comment lines counted as the file has them) and the
    column of a table."""
    bad = np.argwhere(~np.isfinite(a))
    if not bad.size:
        return
    row, col = (int(bad[0][0]), 0) if a.ndim == 1 else (int(bad[0][0]), int(bad[0][1]))
    lines = [i for i, ln in enumerate(path.read_text().splitlines(), 1)
             if ln.strip() and not ln.lstrip().startswith("#")]
    where = f"line {lines[row]}" if row < len(lines) else f"value {row + 1}"
    where += f", column {col + 1}" if a.ndim == 2 and a.shape[1] > 1 else ""
    raise StoreError(str(path), where, f"{float(a[tuple(bad[0])])} is not a finite number")


def _root(folder: Path) -> Path:
    if not folder.is_dir():
        raise StoreError(str(folder), "", "no such folder")
    sub = folder / "datafiles_unprocessed"
    return sub if sub.is_dir() else folder


def _read_pad(d: Path, k: int, n_frames: int) -> np.ndarray:
    """``(2 marks, F + 1, 2)`` image positions [px] of pad ``k``'s two marks (frame 0 = reference)."""
    x0, y0 = _load(d / f"x0_ref_{k}.dat", 1), _load(d / f"y0_ref_{k}.dat", 1)
    xt, yt = _load(d / f"xt_ref_{k}.dat", 2), _load(d / f"yt_ref_{k}.dat", 2)
    for name, a, shape in ((f"x0_ref_{k}.dat", x0, (2,)), (f"y0_ref_{k}.dat", y0, (2,)),
                           (f"xt_ref_{k}.dat", xt, (2, n_frames)), (f"yt_ref_{k}.dat", yt, (2, n_frames))):
        if a.shape != shape:
            raise StoreError(str(d / name), "", f"expected shape {shape} (2 marks x {n_frames} frames as in "
                             f"xt.dat), got {a.shape}")
    for name, a in ((f"x0_ref_{k}.dat", x0), (f"y0_ref_{k}.dat", y0), (f"xt_ref_{k}.dat", xt),
                    (f"yt_ref_{k}.dat", yt)):
        _not_finite_at(d / name, a)     # a pad mark must be seen in every frame
    return np.stack([np.column_stack([x0, xt]), np.column_stack([y0, yt])], axis=2)


def _poly_scatter(pos: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``(2,)`` per-axis scatter of ``pos`` ``(P, F, 2)`` about a cubic in frame index per point."""
    P, F, _ = pos.shape
    k = np.arange(F, dtype=float)
    V = np.vander((k - k.mean()) / max(k.std(), 1.0), _POLY_DEGREE + 1)
    res = []
    for p in range(P):
        ok = valid[p]
        if ok.sum() <= _POLY_DEGREE + 2:
            continue
        c, *_ = np.linalg.lstsq(V[ok], pos[p, ok], rcond=None)
        res.append(pos[p, ok] - V[ok] @ c)
    if not res:
        return np.full(2, np.nan)
    r = np.concatenate(res)
    mad = _MAD * np.median(np.abs(r - np.median(r, axis=0)), axis=0)
    return mad * np.sqrt(F / (F - _POLY_DEGREE - 1))


def _outliers(pos: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``(P, F)`` True where a point's displacement departs from its neighbours' (module step 4)."""
    from scipy.spatial import cKDTree

    ref = pos[:, 0, :]
    ok = np.all(np.isfinite(ref), axis=1)
    out = np.zeros(valid.shape, bool)
    idx = np.flatnonzero(ok)
    if idx.size <= _NEIGHBOURS:
        return out
    d = np.where(valid[..., None], pos - ref[:, None, :], np.nan)[idx]
    _, nb = cKDTree(ref[idx]).query(ref[idx], _NEIGHBOURS + 1)
    dev = d - np.nanmedian(d[nb[:, 1:]], axis=1)
    sig = np.array([_MAD * np.nanmedian(np.abs(dev[..., j] - np.nanmedian(dev[..., j]))) for j in range(2)])
    sig = np.maximum(sig, 1e-12)
    bad = np.any(np.abs(dev) > _OUTLIER_SIGMAS * sig, axis=2)
    out[idx] = bad & np.all(np.isfinite(dev), axis=2)
    return out


def _check_options(root: Path, rate_hz: float, mark_spacing_m: float, moving_pad: int) -> None:
    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise StoreError(str(root), "", f"rate_hz must be positive, got {rate_hz}")
    if not mark_spacing_m > 0:
        raise StoreError(str(root), "", f"mark_spacing_m must be positive, got {mark_spacing_m}")
    if moving_pad not in (1, 2):
        raise StoreError(str(root), "", f"moving_pad must be 1 or 2, got {moving_pad}")


def _read_device(rf: Path) -> tuple[np.ndarray, np.ndarray]:
    """The device's displacement [mm] and force [N], ``(N,)`` each."""
    u_mm = _load(rf / "u_moving_pad.dat", 1)
    f_n = _load(rf / "f_moving_pad.dat", 1)
    if u_mm.size != f_n.size:
        raise StoreError(str(rf / "f_moving_pad.dat"), "",
                         f"has {f_n.size} values but u_moving_pad.dat has {u_mm.size}")
    _not_finite_at(rf / "u_moving_pad.dat", u_mm)
    _not_finite_at(rf / "f_moving_pad.dat", f_n)
    return u_mm, f_n


def _read_points(dd: Path) -> np.ndarray:
    """``(P, F + 1, 2)`` image positions [px] of the tracked points (frame 0 = reference)."""
    x0, y0 = _load(dd / "x0.dat", 1), _load(dd / "y0.dat", 1)
    xt, yt = _load(dd / "xt.dat", 2), _load(dd / "yt.dat", 2)
    if y0.shape != x0.shape:
        raise StoreError(str(dd / "y0.dat"), "", f"has {y0.size} points but x0.dat has {x0.size}")
    if xt.shape[0] != x0.size or yt.shape != xt.shape:
        raise StoreError(str(dd / "yt.dat" if xt.shape[0] == x0.size else dd / "xt.dat"), "",
                         f"expected {x0.size} points x frames like xt.dat {xt.shape}, got {yt.shape}"
                         if xt.shape[0] == x0.size else
                         f"has {xt.shape[0]} rows but x0.dat has {x0.size} points")
    return np.stack([np.column_stack([x0, xt]), np.column_stack([y0, yt])], axis=2)


@dataclass
class _SkinFrame:
    """Steps 1 and 2: the pixel scale [m/px] and the skin frame of the reference image.

    ``R`` rows are skin x and y in image coordinates; ``origin`` [px] is midway between the
    pads' centres; ``shift`` ``(F + 1, 2)`` [px] keeps the fixed pad still in every image."""

    scale: float
    spacing_px: np.ndarray
    spacing_all: np.ndarray
    c_mov: np.ndarray
    c_fix: np.ndarray
    R: np.ndarray
    origin: np.ndarray
    shift: np.ndarray

    def to_skin(self, px: np.ndarray) -> np.ndarray:
        """``(..., F + 1, 2)`` image positions [px] -> skin coordinates [m]."""
        return self.scale * ((px + self.shift - self.origin) @ self.R.T)


def _skin_frame(mov: np.ndarray, fix: np.ndarray, mark_spacing_m: float, dd: Path) -> _SkinFrame:
    """The pixel scale from the marks' spacing in the reference image (step 1) and the skin
    frame: origin midway between the pads, x from the fixed to the moving pad (step 2)."""
    spacing_px = np.array([np.linalg.norm(p[1, 0] - p[0, 0]) for p in (mov, fix)])
    if np.any(spacing_px <= 0):
        raise StoreError(str(dd), "pads", "the two marks of a pad coincide in the reference image")
    scale = mark_spacing_m / float(spacing_px.mean())
    spacing_all = np.array([np.linalg.norm(p[1] - p[0], axis=1) for p in (mov, fix)])   # (2, F+1)
    c_mov, c_fix = mov.mean(axis=0), fix.mean(axis=0)          # (F+1, 2) pad centres [px]
    ex = c_mov[0] - c_fix[0]
    ex = ex / np.linalg.norm(ex)
    R = np.array([ex, [ex[1], -ex[0]]])
    origin = 0.5 * (c_mov[0] + c_fix[0])
    shift = c_fix[0] - c_fix
    return _SkinFrame(scale, spacing_px, spacing_all, c_mov, c_fix, R, origin, shift)


@dataclass
class _FrameTimes:
    """Step 3: the device sample each image is matched to, and the mismatch of that match."""

    i_rest: int
    u_rest: float
    sample: np.ndarray
    mismatch_samples: np.ndarray
    mismatch_m: np.ndarray


def _frames_covered(u: np.ndarray, d: np.ndarray) -> int:
    """How many of the first images show the moving pad no further out than the device went."""
    i_rest = int(np.argmin(u[: max(2, int(np.argmax(u)))]))
    beyond = np.flatnonzero(d > float(np.max(u[i_rest:])) - float(u[i_rest]))
    return int(beyond[0]) if beyond.size else int(d.size)


def _frame_times(u: np.ndarray, d: np.ndarray, scale: float, rate_hz: float, rf: Path,
                 dd: Path) -> _FrameTimes:
    """Match each image's moving-pad displacement ``d`` [m] to the device's displacement
    ``u`` [m]: the first (fractional) sample at which the device reaches it."""
    i_rest = int(np.argmin(u[: max(2, int(np.argmax(u)))]))
    u_rest = float(u[i_rest])
    mono = np.maximum.accumulate(u[i_rest:])
    target = u_rest + d
    if np.any(np.diff(d) < -5 * scale):
        k = int(np.flatnonzero(np.diff(d) < -5 * scale)[0]) + 1
        raise StoreError(str(dd), f"frame {k}", "the moving pad moves back in the images; "
                         "not a monotonic extension")
    if target.max() > mono[-1]:
        n = _frames_covered(u, d)
        keep = (f"the force record covers the first {n} of the {d.size} frames: import those with "
                f"--frames {n}" if n >= 2 else "the force record covers none of the later frames")
        raise StoreError(str(rf / "u_moving_pad.dat"), "",
                         f"the images show the pad {d.max() * 1e3:.3g} mm out, beyond the device's "
                         f"{(mono[-1] - u_rest) * 1e3:.3g} mm: they cannot be matched; {keep}")
    # the first sample at which the device reaches each target, linear between samples
    j = np.searchsorted(mono, target, side="left")
    jm = np.maximum(j - 1, 0)
    frac = (target - mono[jm]) / np.where(j > 0, mono[np.maximum(j, 1)] - mono[jm], 1.0)
    sample = np.where(j > 0, i_rest + jm + frac, float(i_rest))
    sample = np.maximum.accumulate(sample)                     # ties between repeated readings
    kk = np.arange(sample.size, dtype=float)
    line = np.polyval(np.polyfit(kk, sample, 1), kk)
    mismatch_samples = sample - line
    slope = np.gradient(mono) * rate_hz                        # device speed [m/s] along the record
    speed = np.interp(sample - i_rest, np.arange(mono.size), slope)
    mismatch_m = mismatch_samples / rate_hz * speed
    return _FrameTimes(i_rest, u_rest, sample, mismatch_samples, mismatch_m)


def _valid_points(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Steps 4 and 5: validity ``(P, F)``, the per-axis noise ``(2,)`` [m] and the points
    ``(P, F, 3)`` [m] with z = 0 and NaN where invalid."""
    valid = np.all(np.isfinite(pts), axis=2)
    valid &= ~_outliers(pts, valid)
    noise = _poly_scatter(pts, valid)
    points = np.concatenate([np.where(valid[..., None], pts, np.nan), np.zeros(pts.shape[:2] + (1,))], axis=2)
    points[~valid] = np.nan
    return valid, noise, points


def _record_and_track(root: Path, protocol: str, rate_hz: float, u: np.ndarray, f_n: np.ndarray,
                      points: np.ndarray, valid: np.ndarray, t_frames: np.ndarray) -> tuple[RobotRecord,
                                                                                           SurfaceTrack]:
    n = u.size
    nan = np.full(n, np.nan)
    proto = Protocol(protocol, kind="external",
                     description="two-pad extension: pad displacement and reaction force along x; "
                                 "2D image tracking of the skin between the pads")
    try:
        record = RobotRecord(time_s=np.arange(n) / rate_hz, tip_position=np.column_stack([u, nan, nan]),
                             tip_force=np.column_stack([f_n, nan, nan]), protocol=proto)
        track = SurfaceTrack(points=points, valid=valid, time_s=t_frames,
                             point_ids=np.arange(points.shape[0]))
    except SchemaError as exc:
        raise StoreError(str(root), "", str(exc)) from None
    return record, track


def _record_attrs(root: Path, rate_hz: float, times: _FrameTimes) -> dict[str, Any]:
    return {
        "source": str(root.resolve()),
        "time_base": f"nominal: sample i at i / {rate_hz:g} Hz (the device has no clock); quasi-static",
        "nominal_rate_hz": rate_hz,
        "sign": "tip_position x: moving-pad displacement, tip_force x: force of the pad on the skin; "
                "+x when pulling; y, z not measured",
        "rest_sample": times.i_rest,
        "rest_position_m": times.u_rest,
        "frame_samples": [float(s) for s in times.sample],
    }


def _track_attrs(frame: _SkinFrame, mark_spacing_m: float, d: np.ndarray, times: _FrameTimes,
                 noise: np.ndarray, valid: np.ndarray) -> dict[str, Any]:
    return {
        "dimensions": 2,
        # z is not measured by 2D tracking: NaN here, null in the file with the reason beside it;
        # x and y from the scatter (step 5)
        "noise_m": [float(noise[0]), float(noise[1]), float("nan")],
        "noise_m_reason": "z (the third value) is not measured: 2D image tracking",
        "noise_source": "scatter of each point about a cubic in frame index (1.4826 MAD)",
        "pixel_scale_m_per_px": frame.scale,
        "mark_spacing_m": mark_spacing_m,
        "mark_spacing_px": [float(v) for v in frame.spacing_px],
        "mark_spacing_px_range": [float(frame.spacing_all.min()), float(frame.spacing_all.max())],
        "frame": "skin frame: origin midway between the pads' centres, x from the fixed to the moving "
                 "pad, y = z x x (camera looking into the skin), z out of the skin; each image "
                 "translated to keep the fixed pad still",
        "image_x_axis_in_skin": [float(v) for v in frame.R[:, 0]],
        "pad_centre_distance_m": float(np.linalg.norm(frame.c_mov[0] - frame.c_fix[0]) * frame.scale),
        "fixed_pad_drift_px": float(np.max(np.linalg.norm(frame.c_fix - frame.c_fix[0], axis=1))),
        "moving_pad_displacement_m": [float(v) for v in d],
        "frame_match_mismatch_rms_m": float(np.sqrt(np.mean(times.mismatch_m ** 2))),
        "frame_match_mismatch_max_m": float(np.max(np.abs(times.mismatch_m))),
        "frame_match_mismatch_rms_samples": float(np.sqrt(np.mean(times.mismatch_samples ** 2))),
        "invalid_point_frames": int((~valid).sum()),
        "invalid_points": int((~valid).any(axis=1).sum()),
    }


def read_extensometer(folder: str | os.PathLike[str], protocol: str = "extension",
                      rate_hz: float = NOMINAL_RATE_HZ, mark_spacing_m: float = MARK_SPACING_M,
                      moving_pad: int = 1, frames: int | None = None) -> ExtensometerImport:
    """Read a two-pad extensometer + 2D tracking record (module docstring) into skinkit's types.

    Args:
        folder: the record's folder (its root or its ``datafiles_unprocessed``).
        protocol: name of the protocol (kind ``"external"``).
        rate_hz: nominal rate given to the device's samples [Hz]; the model is quasi-static,
            so it only sets the time axis.
        mark_spacing_m: distance between the two marks of one pad [m].
        moving_pad: which pad's marks (``1`` or ``2``) are on the moving pad.
        frames: keep only the first ``frames`` images (the reference image counted), e.g. when
            the camera went on after the force record ended; None: all.

    Raises:
        StoreError: a file is missing, not numeric, of the wrong shape, or the record is not a
            monotonic extension the images can be matched to (one line naming the file).
    """
    root = _root(Path(folder))
    _check_options(root, rate_hz, mark_spacing_m, moving_pad)
    rf, dd = root / "reactionforce", root / "displacement"
    u_mm, f_n = _read_device(rf)
    pts_px = _read_points(dd)
    pads = {k: _read_pad(dd, k, pts_px.shape[1] - 1) for k in (1, 2)}
    if frames is not None:
        if not 2 <= frames <= pts_px.shape[1]:
            raise StoreError(str(dd / "xt.dat"), "", f"--frames {frames}: expected 2 to the "
                             f"{pts_px.shape[1]} frames the images have (the reference image counted)")
        pts_px = pts_px[:, :frames]
        pads = {k: p[:, :frames] for k, p in pads.items()}
    frame = _skin_frame(pads[moving_pad], pads[3 - moving_pad], mark_spacing_m, dd)       # 1., 2.
    pts = frame.to_skin(pts_px)
    pad_mov = frame.to_skin(frame.c_mov)
    d = pad_mov[:, 0] - pad_mov[0, 0]                          # moving-pad displacement in images [m]
    u = u_mm * 1e-3
    times = _frame_times(u, d, frame.scale, rate_hz, rf, dd)                                # 3.
    valid, noise, points = _valid_points(pts)                                               # 4., 5.
    record, track = _record_and_track(root, protocol, rate_hz, u, f_n, points, valid, times.sample / rate_hz)
    return ExtensometerImport(record, track, _record_attrs(root, rate_hz, times),
                              _track_attrs(frame, mark_spacing_m, d, times, noise, valid))


def import_extensometer(folder: str | os.PathLike[str], experiment: str | os.PathLike[str],
                        protocol: str = "extension", overwrite: bool = False,
                        rate_hz: float = NOMINAL_RATE_HZ, mark_spacing_m: float = MARK_SPACING_M,
                        moving_pad: int = 1, frames: int | None = None) -> ExtensometerImport:
    """Read ``folder`` (:func:`read_extensometer`, ``frames`` included) and write a new experiment
    file ``experiment``: the record and the track named ``protocol``, with their facts as attributes.

    The file is written under a temporary name and renamed on success, so a failure leaves
    nothing behind; an existing ``experiment`` is refused unless ``overwrite``.
    """
    from skinkit.store.experiment import create_experiment

    out = Path(experiment)
    if out.exists() and not overwrite:
        raise StoreError(str(out), "", "already exists (pass --overwrite to replace it)")
    if out.is_dir():
        raise StoreError(str(out), "", "is a directory")
    if not out.parent.is_dir():
        raise StoreError(str(out), "", "its folder does not exist")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent)
    except OSError as exc:    # before the folder is read; named as given, not the hidden file
        raise StoreError(str(out), "", f"cannot be written in {out.parent} ({exc.strerror or exc})") from None
    os.close(fd)
    try:
        imp = read_extensometer(folder, protocol, rate_hz, mark_spacing_m, moving_pad, frames)
        with create_experiment(tmp, overwrite=True) as exp:
            exp.set_metadata(operator="external (skinkit import-extensometer)",
                             source=str(imp.record_attrs["source"]))
            exp.write_record(imp.record, rate_hz=rate_hz)
            exp.set_record_attrs(protocol, session_index=0, **imp.record_attrs)
            exp.write_track(protocol, imp.track)
            exp.set_track_attrs(protocol, **imp.track_attrs)
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return imp
