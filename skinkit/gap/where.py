"""Where a calibrated model misses: the noise-normalised residual decomposed along axes.

The residual is exactly the fit's (:meth:`skinkit.inverse.objective.Objective.residual` with the
``"noise"`` weighting): z = whiten((y_pred − Y)/σ) on the entries ``ChannelPrediction.mask`` keeps,
so Σz² over every cell of one partition is the fit's χ². It is split along five axes:

* ``protocol``; ``channel`` (``tip_force``, ``tip_position``, ``surface x|y|z``);
* ``phase``: loading / unloading / hold of the protocol's drive (partition ``direction``) and
  first cycle / later cycles (partition ``cycle``);
* ``region``: the partitions of the tracked points' reference positions that the model's
  geometry supplies (:mod:`skinkit.schemas.regions`; by default radial bands ``radius`` and
  angular sectors ``sector`` around ``centre``), and a per-point map;
* ``frequency``: bands of each residual series' spectrum relative to the band holding 95 % of
  the drive's power (Parseval: the bands partition the χ² of every series).

Each cell is tested against the noise: raw χ² upper tail, and for ``significant`` an F test that
allows for the noise level itself being estimated from the record, with Holm's correction over
every cell of every axis. Whiteness (Ljung–Box) and cross-correlation with the drive (a
portmanteau of the regression on the lagged drive) are reported per protocol and channel.
The rules and their justification: ``docs/guide/gap-diagnosis.md``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np
from scipy import stats

from skinkit.errors import SchemaError
from skinkit.fem.threads import single_threaded_blas
from skinkit.forward import noise_model as nm
from skinkit.gap.drive import Drive, _drive_channel, make_drive
from skinkit.gap.lines import ALPHA_SHARE, Line, search
from skinkit.inverse.objective import WEIGHTINGS, Objective
from skinkit.schemas import Channel, Observations, Prediction
from skinkit.schemas.observations import CHANNELS
from skinkit.schemas.regions import RegionPartition, RegionProvider, polar_partitions

AXES = ("protocol", "channel", "phase", "region", "frequency")
PHASES = ("loading", "unloading", "hold")
CYCLES = ("first cycle", "later cycles")
BANDS = ("below input band", "input band", "1-10x input band", "above 10x input band")

#: variance of the second-differences noise estimate: Δ²e has autocovariances 6, −4, 1 (σ⁴ units),
#: so Var(mean (Δ²e)²) = 2·(36 + 2·16 + 2·1)σ⁴/n and the relative variance of σ̂² is 2/(n·36/70)
_SD2_EFFICIENCY = 36.0 / 70.0
#: asymptotic efficiency of the MAD as a scale estimate of Gaussian data
_MAD_EFFICIENCY = 0.37
#: the shortest rest segment the reader accepts (skinkit.forward.observations._MIN_REST)
_MIN_REST = 50


# ----------------------------------------------------------------------------------------- results
@dataclass
class Cell:
    """One cell of one axis: its χ² against the noise and its share of the axis's excess.

    ``partition`` names the partition of the axis the cell belongs to (``phase`` has
    ``direction`` and ``cycle``; ``region`` has ``radius`` and ``sector``, and those the model's
    geometry adds, e.g. ``twopad``; the others one, named after the axis): shares sum to 1 within
    a partition. ``noise_dof`` is the effective number of samples behind the noise level of the
    cell's samples (inf: the noise was known).
    """

    axis: str
    label: str
    chi2: float
    dof: float
    chi2_per_dof: float
    p_value: float
    significant: bool
    share: float
    n: int
    partition: str = ""
    noise_dof: float = float("inf")

    def to_dict(self) -> dict[str, Any]:
        """The cell as a plain dict (JSON-ready)."""
        return {"axis": self.axis, "label": self.label, "chi2": self.chi2, "dof": self.dof,
                "chi2_per_dof": self.chi2_per_dof, "p_value": self.p_value,
                "significant": bool(self.significant), "share": self.share, "n": int(self.n),
                "partition": self.partition, "noise_dof": _json_float(self.noise_dof)}


@dataclass
class GapLocation:
    """The whole residual against the noise, and every cell of every axis.

    ``significant``: there is a gap — the whole residual's test or any cell's, all members of
    one Holm family at ``alpha`` (so on pure noise it is True in at most ``alpha`` of sessions).
    ``point_map``: protocol -> ``(P,)`` χ²/dof per tracked point (NaN where unobserved).
    ``whiteness`` / ``cross_correlation``: ``"<protocol>/<channel>"`` -> test figures.
    ``input_band``: protocol -> ``(f_lo, f_hi)`` [Hz] holding 95 % of the drive's power.
    ``family_p``: the family's p-value — the smallest ``alpha`` at which ``significant`` would
    hold (the smallest Holm-adjusted p of a member above its dof, or of the line family scaled by
    its share of the level), for a caller that combines this family with other tests.
    ``lines``: periodic components above ten times the drive's band (:mod:`skinkit.gap.lines`);
    one makes the gap significant on its own.
    """

    chi2: float
    dof: float
    chi2_per_dof: float
    p_value: float
    significant: bool
    cells: list[Cell]
    point_map: dict[str, np.ndarray] = field(default_factory=dict)
    whiteness: dict[str, dict] = field(default_factory=dict)
    cross_correlation: dict[str, dict] = field(default_factory=dict)
    noise_dof: float = float("inf")
    input_band: dict[str, tuple[float, float]] = field(default_factory=dict)
    family_p: float = float("nan")
    lines: list[Line] = field(default_factory=list)

    def ranked(self) -> list[Cell]:
        """The significant cells, largest share of their partition's excess first."""
        return sorted((c for c in self.cells if c.significant), key=lambda c: (-c.share, -c.chi2_per_dof))

    def axis(self, name: str) -> list[Cell]:
        """The cells of axis ``name``."""
        return [c for c in self.cells if c.axis == name]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN and inf become None)."""
        return {"chi2": self.chi2, "dof": self.dof, "chi2_per_dof": self.chi2_per_dof,
                "p_value": self.p_value, "significant": bool(self.significant),
                "family_p": _json_float(self.family_p), "noise_dof": _json_float(self.noise_dof),
                "cells": [c.to_dict() for c in self.cells],
                "point_map": {k: [_json_float(x) for x in v] for k, v in self.point_map.items()},
                "whiteness": {k: {a: _json_float(b) for a, b in v.items()}
                              for k, v in self.whiteness.items()},
                "cross_correlation": {k: {a: _json_float(b) for a, b in v.items()}
                                      for k, v in self.cross_correlation.items()},
                "input_band": {k: list(v) for k, v in self.input_band.items()},
                "lines": [ln.to_dict() for ln in self.lines]}


def _json_float(x: Any) -> Any:
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    x = float(x)
    return x if np.isfinite(x) else None


# ---------------------------------------------------------------------------------------- samples
@dataclass
class Samples:
    """The residual of one protocol's channel with the coordinates every axis groups by.

    ``full``: the whitened noise-normalised residual, the shape of the channel's values, 0 off
    ``mask``; ``z`` ``(m,)`` = ``full[mask]`` (the order of ``Objective.residual``); per sample
    ``time_s``, ``component`` (0, 1, 2 = x, y, z), ``point`` (−1 for tip channels), ``reference``
    ``(m, 3)`` [m] (NaN for tip channels), ``phase`` (index into :data:`PHASES`, −1 without a
    drive), ``cycle``. ``noise_dof``, ``noise_shared`` ``(k,)``: how each component's noise
    level was estimated (:func:`noise_dof`). ``dt`` [s]: the channel's median sample interval; ``drive``: the
    protocol's :class:`Drive` (None when it has none); ``series_time_s`` ``(T,)``: the channel's
    time base. ``noise_ar``: per component ``(φ (p,), bias (p,), cov (p, p))``, the AR noise
    model's coefficients and their estimate's bias and covariance
    (:func:`skinkit.forward.noise_model.ar_sampling`; p = 0: white), empty for a channel
    without one or whose coefficients were given. ``raw``: a tip channel's residual, prediction
    minus record [unit], 0 off ``mask`` (None for points).
    """

    protocol: str
    channel: str
    full: np.ndarray
    mask: np.ndarray
    z: np.ndarray
    time_s: np.ndarray
    component: np.ndarray
    point: np.ndarray
    reference: np.ndarray
    phase: np.ndarray
    cycle: np.ndarray
    noise_dof: np.ndarray
    noise_shared: np.ndarray
    dt: float
    drive: Drive | None = None
    series_time_s: np.ndarray | None = None
    noise_ar: tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...] = ()
    raw: np.ndarray | None = None

    @property
    def is_points(self) -> bool:
        """True for a channel of tracked points."""
        return self.full.ndim == 3

    @property
    def labels(self) -> list[str]:
        """The ``channel`` axis label of each component."""
        k = self.full.shape[-1]
        if self.is_points:
            return [f"surface {'xyz'[j]}" for j in range(k)]
        return [self.channel] * k


def ar_uncertainty(ch: Channel) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]:
    """Per component of a tip channel with an AR noise model fitted to a rest segment, its
    coefficients with their estimate's bias and covariance ``(φ (p,), bias (p,), cov (p, p))``
    (:attr:`Samples.noise_ar`); empty when the channel has no AR model or its source names no
    rest segment (coefficients given)."""
    if ch.is_points or ch.noise_ar is None:
        return ()
    n = nm.rest_samples(ch.noise_source or "")
    if n is None:
        return ()
    return tuple((np.asarray(a, float), *nm.ar_sampling(a, n)) for a in ch.noise_ar)


def noise_dof(ch: Channel) -> tuple[np.ndarray, np.ndarray]:
    """How uncertain each component's noise level is: ``(n_est, n_shared)``, both ``(k,)``.

    ``n_est``: effective number of samples behind the variance estimate, Var(σ̂²/σ²) = 2/n_est
    (inf: known). ``n_shared``: for a level estimated by second differences over the whole
    record, its number of samples (the estimate then shares its noise with every residual sample
    of the channel, see ``docs/guide/gap-diagnosis.md``); 0 otherwise.

    From ``ch.noise_source`` (``skinkit.forward.observations``): a tracker's or a declared level,
    or the sensor resolution floor, is known; second differences over the record count 36/70 of
    its samples (:data:`_SD2_EFFICIENCY`); a rest segment its samples less the 3 of its quadratic
    (from the source text, else recomputed from the record, else the shortest accepted, 50);
    MAD-based estimates (neighbour differences) 0.37 of their samples. Anything else
    (``"unknown"``) is taken as second differences over the record, the reader's default.
    """
    src = (ch.noise_source or "").lower()
    k = ch.values.shape[-1]
    n = ch.valid.reshape(-1, k).sum(axis=0).astype(float)
    zero = np.zeros(k)
    if any(w in src for w in ("tracker", "declared", "known", "resolution", "truth")):
        return np.full(k, np.inf), zero
    if "neighbour" in src or "mad" in src:
        return _MAD_EFFICIENCY * n, zero
    if "rest segment" not in src or ch.is_points:
        return _SD2_EFFICIENCY * n, n
    from skinkit.forward.observations import SECOND_DIFFERENCES, sample_noise

    n_est, shared = _SD2_EFFICIENCY * n, n.copy()
    got = re.search(r"rest segment \((\d+) samples", src)
    if got and SECOND_DIFFERENCES not in src:
        return np.full(k, float(int(got.group(1)) - 3)), zero
    for j in range(k):
        s, how = sample_noise(ch.values[:, j])
        match = np.isclose(s, ch.noise[j], rtol=1e-9)
        seg = re.search(r"rest segment \((\d+) samples", how)
        if match and seg and how.startswith("rest segment"):
            n_est[j], shared[j] = int(seg.group(1)) - 3, 0.0
        elif not (match and how.startswith(SECOND_DIFFERENCES)):
            n_est[j], shared[j] = _MIN_REST - 3, 0.0   # cannot tell: the shortest rest segment accepted
    return n_est, shared


def _check(observations: Any, prediction: Any, protocols: Sequence[str] | None) -> list[str]:
    if not isinstance(observations, Observations):
        raise SchemaError("observations", f"expected Observations, got {type(observations).__name__}")
    if not isinstance(prediction, Prediction):
        raise SchemaError("prediction", f"expected a Prediction, got {type(prediction).__name__}")
    for p in prediction.protocols:
        if p not in observations.protocols:
            raise SchemaError("prediction", f"predicts protocol {p!r}, which the session does not have "
                              f"(it has {observations.names})")
    names = list(prediction.protocols) if protocols is None else list(protocols)
    for p in names:
        if p not in prediction.protocols:
            raise SchemaError("protocols", f"{p!r} is not predicted "
                              f"(the prediction has {list(prediction.protocols)})")
    if not names:
        raise SchemaError("prediction", "predicts no protocol")
    return names


def samples(observations: Observations, prediction: Prediction, *, weighting: str = "noise",
            protocols: Sequence[str] | None = None) -> list[Samples]:
    """Per protocol and predicted channel, the weighted residual with its coordinates.

    ``weighting``: as :class:`~skinkit.inverse.objective.Objective` (``"noise"`` gives the χ²
    residual); ``protocols``: restrict to these (None: all the prediction has). Σ z² over the
    result equals ``Objective(...).residual(prediction).z`` squared and summed, to rounding.
    """
    names = _check(observations, prediction, protocols)
    if weighting not in WEIGHTINGS:
        raise SchemaError("weighting", f"must be one of {list(WEIGHTINGS)}, got {weighting!r}")
    for proto in names:
        for cname, cp in prediction.protocols[proto].items():
            ch = observations[proto].channel(cname)
            if np.shape(cp.values) != ch.values.shape:
                raise SchemaError(f"prediction[{proto!r}][{cname!r}]",
                                  f"has shape {np.shape(cp.values)}, the observed channel {ch.values.shape}")
    obj = Objective(None, observations, [], weighting)
    # the Objective's own residual, so that Σz² is the fit's χ² whatever the weighting, and a
    # model error the observations carry (mean and covariance) is whitened as in the fit
    res = obj.residual(Prediction({p: prediction.protocols[p] for p in names}, dict(prediction.methods),
                                  dict(prediction.inputs), dict(prediction.info)), jacobian=False)
    zmap = {(p, c): res.z[sl] for p, c, sl in res.blocks}
    out: list[Samples] = []
    for proto in names:
        po = observations[proto]
        chans = prediction.protocols[proto]
        dname = _drive_channel(po, set(chans), prediction.inputs.get(proto))
        drive = make_drive(po.channels[dname]) if dname else None
        for cname, cp in chans.items():
            ch = po.channel(cname)
            _, keep = obj.weights(proto, cname, ch)
            m = cp.mask(ch) & keep
            if not m.any():
                continue
            full = np.zeros(ch.values.shape)
            full[m] = zmap[(proto, cname)]
            idx = np.nonzero(m)
            if ch.is_points:
                pt, ti, comp = idx
                ref = ch.reference if ch.reference is not None else np.nan_to_num(ch.values[:, 0])
                ref = np.pad(ref, ((0, 0), (0, 3 - ref.shape[1])))
                reference = ref[pt]
            else:
                ti, comp = idx
                pt = np.full(ti.size, -1)
                reference = np.full((ti.size, 3), np.nan)
            if drive is not None:
                di = drive.index(ch.time_s)
                phase, cycle = drive.phase[di][ti], drive.cycle[di][ti]
            else:
                phase, cycle = np.full(ti.size, -1, np.int8), np.zeros(ti.size, int)
            dts = np.diff(ch.time_s)
            dt = float(np.median(dts[dts > 0])) if np.any(dts > 0) else 0.0
            raw = None if ch.is_points else np.where(m, np.asarray(cp.values, float) - ch.values, 0.0)
            out.append(Samples(proto, cname, full, m, full[m], ch.time_s[ti], comp, pt, reference,
                               phase, cycle, *noise_dof(ch), dt, drive, ch.time_s, ar_uncertainty(ch), raw))
    if not out:
        raise SchemaError("prediction", "covers no observed sample (does the session have the channels "
                          "the model predicts?)")
    return out


# ------------------------------------------------------------------------------------- partitions
@dataclass
class _Partition:
    axis: str
    name: str
    labels: list[str]
    chi2: np.ndarray          # (L,)
    nmat: np.ndarray          # (L, G) samples of each noise group in each cell
    gmat: np.ndarray          # (L, G) the same weighted by the second-difference gain |1 - e^{iω}|⁴
    # (L, G) relative variance of each noise group's prewhitened level in each cell that the
    # uncertainty of its AR coefficients brings (None: 0), and (bmat) the relative shift of that
    # level their bias brings. A white cell in time holds every frequency alike, where the
    # coefficients' error averages out to first order (the mean of ∂ log|A|²/∂φ over all
    # frequencies is 0); a band of the spectrum does not.
    qmat: np.ndarray | None = None
    bmat: np.ndarray | None = None


class _Table:
    """Every sample of every :class:`Samples`, flattened, with one code array per partition."""

    def __init__(self, ss: list[Samples], regions: RegionProvider) -> None:
        self.ss = ss
        k = [s.full.shape[-1] for s in ss]
        self.offset = np.concatenate([[0], np.cumsum(k)]).astype(int)
        self.G = int(self.offset[-1])
        self.noise_dof = np.concatenate([s.noise_dof for s in ss])
        self.noise_shared = np.concatenate([s.noise_shared for s in ss])
        self.z2 = np.concatenate([s.z ** 2 for s in ss])
        self.g = np.concatenate([self.offset[i] + s.component for i, s in enumerate(ss)])
        self.N = self.z2.size
        self.regions = regions

    def _tally(self, axis: str, name: str, code: np.ndarray, labels: list[str]) -> _Partition:
        L, G = len(labels), self.G
        sel = code >= 0
        c = code[sel]
        chi2 = np.bincount(c, weights=self.z2[sel], minlength=L)
        nmat = np.bincount(c * G + self.g[sel], minlength=L * G).reshape(L, G).astype(float)
        # a time-domain sample meets the second differences with gain Σ(1, −2, 1)² = 6
        return _Partition(axis, name, labels, chi2, nmat, 6.0 * nmat)

    def partitions(self) -> list[_Partition]:
        ss = self.ss
        out = []
        protos = list(dict.fromkeys(s.protocol for s in ss))
        code = np.concatenate([np.full(s.z.size, protos.index(s.protocol)) for s in ss])
        out.append(self._tally("protocol", "protocol", code, protos))
        labs = list(dict.fromkeys(lab for s in ss for lab in s.labels))
        code = np.concatenate([np.array([labs.index(lab) for lab in s.labels])[s.component] for s in ss])
        out.append(self._tally("channel", "channel", code, labs))
        code = np.concatenate([s.phase.astype(int) for s in ss])
        out.append(self._tally("phase", "direction", code, list(PHASES)))
        code = np.concatenate([np.minimum(s.cycle, 1).astype(int) for s in ss])
        out.append(self._tally("phase", "cycle", code, list(CYCLES)))
        out.extend(self._regions())
        out.append(self._frequency())
        return out

    def _regions(self) -> list[_Partition]:
        """The ``region`` partitions of the provider, on every tracked point's reference position."""
        pts = [s for s in self.ss if s.is_points]
        if not pts:
            return []
        # each protocol's points once: the provider labels points, every sample of a point
        # shares its label
        refs, where = [], []
        n = 0
        for s in pts:
            _, first, inv = np.unique(s.point, return_index=True, return_inverse=True)
            refs.append(s.reference[first, :2])
            where.append(n + inv.ravel())
            n += first.size
        points = np.concatenate(refs)
        parts: list[_Partition] = []
        owner: dict[str, str] = {}         # cell label -> its partition: cells are keyed by label
        for rp in self.regions(points):
            if not isinstance(rp, RegionPartition):
                raise SchemaError("regions", "a region provider must give RegionPartition records, got "
                                  f"{type(rp).__name__}")
            if any(p.name == rp.name for p in parts):
                raise SchemaError(f"regions.{rp.name}", "two partitions of the region axis have this name")
            code = rp.codes(points.shape[0])
            for lab in rp.cells:
                if lab in owner:
                    raise SchemaError(f"regions.{rp.name}", f"cell {lab!r} is also a cell of partition "
                                      f"{owner[lab]!r}: labels must be unique along the region axis")
                owner[lab] = rp.name
            it = iter(where)
            full = np.concatenate([code[next(it)] if s.is_points else np.full(s.z.size, -1) for s in self.ss])
            parts.append(self._tally("region", rp.name, full, list(rp.cells)))
        return parts

    def _frequency(self) -> _Partition:
        """χ² per band via Parseval, per series (tip channel component, or point and component)."""
        L, G = len(BANDS), self.G
        chi2, nmat, gmat = np.zeros(L), np.zeros((L, G)), np.zeros((L, G))
        qmat, bmat = np.zeros((L, G)), np.zeros((L, G))
        for i, s in enumerate(self.ss):
            if s.drive is None or s.dt <= 0:
                continue
            ax = 1 if s.is_points else 0
            N = s.full.shape[ax]
            if N < 4:
                continue
            f = np.fft.rfftfreq(N, s.dt)
            wb = np.full(f.size, 2.0)
            wb[0] = 1.0
            if N % 2 == 0:
                wb[-1] = 1.0
            power = np.abs(np.fft.rfft(s.full, axis=ax)) ** 2 * (wb / N)[:, None]  # (nb, k) or (P, nb, k)
            lo, hi = s.drive.band
            b = np.where(f < lo, 0, np.where(f <= hi, 1, np.where(f <= 10 * hi, 2, 3)))
            frac = np.bincount(b, weights=wb, minlength=L) / N                    # (L,) dof share per band
            gain = 16.0 * np.sin(np.pi * f * s.dt) ** 4                           # |1 − e^{iω}|⁴
            gfrac = np.bincount(b, weights=wb * gain, minlength=L) / N
            per = power.sum(axis=0) if s.is_points else power                    # (nb, k)
            for j in range(L):
                chi2[j] += float(per[b == j].sum())
            nval = s.mask.sum(axis=ax)
            nval = nval.sum(axis=0) if s.is_points else nval                     # (k,)
            nmat[:, self.offset[i]: self.offset[i + 1]] += frac[:, None] * nval[None, :]
            gmat[:, self.offset[i]: self.offset[i + 1]] += gfrac[:, None] * nval[None, :]
            for j, (phi, bias, cov) in enumerate(s.noise_ar):
                if not phi.size:
                    continue
                # the band's mean relative gain error, h·δ with δ ~ (bias, cov): mean h·bias,
                # variance h cov hᵀ
                grad = nm.log_gain_gradient(phi, 2 * np.pi * f * s.dt) * wb[:, None]      # (nb, p)
                h = np.stack([grad[b == c].sum(axis=0) for c in range(L)])             # (L, p)
                cnt = np.bincount(b, weights=wb, minlength=L)
                h = h / np.where(cnt > 0, cnt, 1.0)[:, None]
                q = np.einsum("lp,pq,lq->l", h, cov, h)
                # several series in one group: their shares of the group's samples in the cell
                qmat[:, self.offset[i] + j] += q * frac * nval[j]
                bmat[:, self.offset[i] + j] += (h @ bias) * frac * nval[j]
        # the group's figures as the sample-weighted means over its series
        qmat = np.where(nmat > 0, qmat / np.where(nmat > 0, nmat, 1.0), 0.0)
        bmat = np.where(nmat > 0, bmat / np.where(nmat > 0, nmat, 1.0), 0.0)
        return _Partition("frequency", "frequency", list(BANDS), chi2, nmat, gmat, qmat, bmat)


# ------------------------------------------------------------------------------------------- tests
def _noise_dof_of(table: _Table, nmat: np.ndarray, gmat: np.ndarray, qmat: np.ndarray | None = None,
                  bmat: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(m, ν)`` per cell: under the null, χ²/dof of the cell is m·F(dof, ν) (docs/guide/gap-diagnosis.md).

    A cell's statistic is Σ_g w_g a_g / b_g: w_g its share of samples of noise group g (one
    component of one protocol's channel), a_g their χ²/n at the true noise, b_g = σ̂_g²/σ_g² with
    ν_g = n_est samples behind it (b ~ χ²_ν/ν: E 1/b = ν/(ν−2), Var 1/b = 2ν²/((ν−2)²(ν−4))).
    When σ̂_g comes from second differences over the whole record, a_g and b_g share noise:
    Cov = (2/n_shared)·ḡ/6, ḡ the cell's mean gain of the second differences (6 in time,
    16 sin⁴(πf·dt) at frequency f). The mean m and relative variance v of the denominator's
    inverse, Σ w_g/b_g, are matched by m·ν/χ²_ν with 2/(ν−4) = v/m².

    ``qmat``, ``bmat`` ``(L, G)``: a further relative variance and shift of the prewhitened
    noise's level per cell, independent of the level's estimate (:attr:`_Partition.qmat`: the
    AR coefficients' uncertainty and bias in a band of the spectrum)."""
    nd, sh = table.noise_dof, table.noise_shared
    fin = np.isfinite(nd) & (nd > 4.5)
    nu = np.where(fin, nd, np.inf)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean1 = np.where(fin, 2.0 / (nu - 2.0), 0.0)                               # E 1/b − 1
        var1 = np.where(fin, 2.0 * nu ** 2 / ((nu - 2.0) ** 2 * (nu - 4.0)), 0.0)  # Var 1/b
        covu = np.where(sh > 0, 2.0 / np.where(sh > 0, sh, 1.0) / 6.0, 0.0)
        n = nmat.sum(axis=1)
        m = 1.0 + (nmat @ mean1 - (gmat * 1.0) @ covu) / n
        v = (nmat ** 2 @ var1 - 2.0 * (nmat * gmat) @ covu) / n ** 2
        if qmat is not None:
            v = v + np.sum(nmat ** 2 * qmat, axis=1) / n ** 2
        if bmat is not None:
            m = m + np.sum(nmat * bmat, axis=1) / n
        m = np.maximum(m, 1.0)           # never credit the shared noise with a smaller mean
        dof = np.where(v > 0, 4.0 + 2.0 * m ** 2 / v, np.inf)
    return m, dof


def _p_values(chi2: np.ndarray, dof: np.ndarray, scale: np.ndarray,
              ndof: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(raw χ² upper tail, upper tail of χ²/dof against scale·F(dof, ndof)) per cell."""
    ok = dof > 0
    d = np.where(ok, dof, 1.0)
    p = np.where(ok, stats.chi2.sf(chi2, d), np.nan)
    pf = np.where(ok, stats.chi2.sf(chi2 / scale, d), np.nan)
    fin = ok & (ndof < 1e12)
    if fin.any():
        pf[fin] = stats.f.sf(chi2[fin] / d[fin] / scale[fin], d[fin], ndof[fin])
    return p, pf


def holm_adjusted(p: np.ndarray) -> np.ndarray:
    """Holm-adjusted p-values of ``p`` (NaN counts as 1): member i is rejected at family-wise
    level α exactly when its adjusted value is ≤ α, so the smallest adjusted value over a set of
    members is the family's p-value for "at least one of them"."""
    p = np.where(np.isfinite(p), np.asarray(p, float), 1.0)
    K = p.size
    order = np.argsort(p, kind="stable")
    adj = np.minimum(np.maximum.accumulate(p[order] * (K - np.arange(K))), 1.0)
    out = np.empty(K)
    out[order] = adj
    return out


def holm(p: np.ndarray, alpha: float) -> np.ndarray:
    """Holm–Bonferroni rejections of the p-values ``p`` (NaN: never) at family-wise level ``alpha``."""
    ok = holm_adjusted(p) <= alpha
    return ok & np.isfinite(np.asarray(p, float))


def _cells(table: _Table, n_params: int, alpha: float,
           whole: tuple[float, float, float]) -> tuple[list[Cell], bool, float]:
    """Every cell, tested; whether the whole residual's test ``whole`` = (χ², dof, p) is
    rejected, as one more member of the same Holm family; and the family's p-value (the
    smallest Holm-adjusted p of a member above its dof: 1 when none is)."""
    cells, pfs = [], []
    for part in table.partitions():
        n = part.nmat.sum(axis=1)
        keep = n > 0
        if not keep.any():
            continue
        chi2, nmat, gmat = part.chi2[keep], part.nmat[keep], part.gmat[keep]
        qmat = None if part.qmat is None else part.qmat[keep]
        bmat = None if part.bmat is None else part.bmat[keep]
        labels = [lab for lab, k in zip(part.labels, keep, strict=True) if k]
        n = n[keep]
        dof = n - n_params * n / table.N
        scale, ndof = _noise_dof_of(table, nmat, gmat, qmat, bmat)
        p, pf = _p_values(chi2, dof, scale, ndof)
        excess = np.maximum(chi2 - dof, 0.0)
        tot = excess.sum()
        share = excess / tot if tot > 0 else np.zeros_like(excess)
        for j, lab in enumerate(labels):
            cells.append(Cell(part.axis, lab, float(chi2[j]), float(dof[j]),
                              float(chi2[j] / dof[j]) if dof[j] > 0 else float("nan"), float(p[j]), False,
                              float(share[j]), int(round(n[j])), part.name, float(ndof[j])))
        pfs.append(pf)
    pall = np.concatenate([[whole[2]], *pfs])
    adj = holm_adjusted(pall)
    sig = (adj <= alpha) & np.isfinite(pall)
    above = np.array([whole[0] > whole[1]] + [c.chi2 > c.dof for c in cells])
    for c, s in zip(cells, sig[1:], strict=True):
        c.significant = bool(s) and c.chi2 > c.dof
    family_p = float(adj[above].min()) if above.any() else 1.0
    return cells, bool(sig[0]) and whole[0] > whole[1], family_p


def _ljung_box(full: np.ndarray, mask: np.ndarray, ax: int, h: int) -> tuple[float, float]:
    """Ljung–Box Q of the pooled autocorrelation over every series along ``ax`` (zero mean known):
    under white noise r_k = Σ z_t z_{t+k} / Σ z² has variance n_k/n_0² (n_k pairs), so
    Q = Σ_k r_k² n_0²/n_k is χ² with h degrees of freedom."""
    Z = np.moveaxis(full, ax, 0).reshape(full.shape[ax], -1)
    M = np.moveaxis(mask, ax, 0).reshape(full.shape[ax], -1)
    n0, s0 = float(M.sum()), float(np.sum(Z * Z))
    if s0 <= 0:
        return float("nan"), float("nan")
    q = 0.0
    for k in range(1, h + 1):
        nk = float(np.sum(M[:-k] & M[k:]))
        if nk > 0:
            q += (float(np.sum(Z[:-k] * Z[k:])) / s0) ** 2 * n0 * n0 / nk
    return q, float(stats.chi2.sf(q, h))


def _cross(full: np.ndarray, mask: np.ndarray, ax: int, X: np.ndarray, h: int) -> tuple[float, int, float]:
    """Portmanteau of the residual against the lagged drive: every series z (along ``ax``) is
    regressed on the columns of X lagged by 0..h samples, on its own valid samples; with r the
    regressors' rank and n the valid samples, n ‖P z‖²/‖z‖² is n·Beta(r/2, (n−r)/2) when z is
    white and independent of X (mean r, variance below 2r), so the sum over series is compared
    with χ² of Σ r degrees of freedom (slightly conservative)."""
    Z = np.moveaxis(full, ax, 0).reshape(full.shape[ax], -1)
    M = np.moveaxis(mask, ax, 0).reshape(full.shape[ax], -1)
    use = M.sum(axis=0) > 0
    Z, M = Z[:, use], M[:, use]
    n, R = X.shape
    Xp = np.vstack([np.zeros((h, R)), X])
    width = R * (h + 1)
    # series sharing a mask share the Gram matrix of their valid rows (tips: one; points: few)
    keys: dict[bytes, int] = {}
    inverse = np.array([keys.setdefault(c.tobytes(), len(keys)) for c in np.packbits(M, axis=0).T], dtype=int)
    patterns = [M[:, int(np.argmax(inverse == i))] for i in range(len(keys))]
    Gs = np.zeros((len(patterns), width, width))
    C = np.zeros((width, Z.shape[1]))
    step = 1 << 16
    for a in range(0, n, step):
        b = min(n, a + step)
        U = np.concatenate([Xp[a + h - k: b + h - k] for k in range(h + 1)], axis=1)
        for i, pat in enumerate(patterns):
            Uv = U[pat[a:b]]
            Gs[i] += Uv.T @ Uv
        C += U.T @ Z[a:b]
    stat, dof = 0.0, 0
    for i in range(len(patterns)):
        cols = np.flatnonzero(inverse == i)
        lam, V = np.linalg.eigh(Gs[i])
        keep = lam > 1e-10 * max(lam.max(), 1e-300)
        r = int(keep.sum())
        nval = float(patterns[i].sum())
        if r == 0 or nval <= r:
            continue
        proj = (V[:, keep].T @ C[:, cols]) / np.sqrt(lam[keep])[:, None]
        ss = np.sum(Z[:, cols] ** 2, axis=0)
        ok = ss > 0
        stat += float(np.sum(nval * np.sum(proj[:, ok] ** 2, axis=0) / ss[ok]))
        dof += r * int(ok.sum())
    if dof == 0:
        return float("nan"), 0, float("nan")
    return stat, dof, float(stats.chi2.sf(stat, dof))


def _series_tests(ss: list[Samples], alpha: float) -> tuple[dict[str, dict], dict[str, dict]]:
    white, cross = {}, {}
    for s in ss:
        key = f"{s.protocol}/{s.channel}"
        ax = 1 if s.is_points else 0
        T = s.full.shape[ax]
        h = min(10, T // 5) if s.is_points else min(20, T // 10)
        if h >= 1:
            q, p = _ljung_box(s.full, s.mask, ax, h)
            white[key] = {"statistic": q, "lags": h, "p_value": p}
        if s.drive is None or s.channel == s.drive.channel:
            continue            # the drive's own noise is in the regressors: not a test of the model
        hx = min(3, T // 10) if s.is_points else min(10, T // 20)
        if T < 8:
            continue
        t = s.series_time_s
        lev = np.interp(t, s.drive.time_s, s.drive.level)
        rate = np.interp(t, s.drive.time_s, s.drive.rate)
        X = np.stack([lev - lev.mean(), rate - rate.mean()], axis=1)
        X = X / np.maximum(X.std(axis=0), 1e-300)
        stat, dof, p = _cross(s.full, s.mask, ax, X, hx)
        cross[key] = {"statistic": stat, "lags": hx, "dof": dof, "p_value": p}
    # one flag per test family: Bonferroni over the series tested
    for fam, word in ((white, "white"), (cross, "independent")):
        for v in fam.values():
            v[word] = bool(not (v["p_value"] <= alpha / max(len(fam), 1)))
    return white, cross


def _point_map(ss: list[Samples], n_params: int, N: int) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for s in ss:
        if not s.is_points or s.protocol in out:
            continue
        P = s.full.shape[0]
        chi2 = np.bincount(s.point, weights=s.z ** 2, minlength=P)
        n = np.bincount(s.point, minlength=P).astype(float)
        dof = n * (1.0 - n_params / N)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[s.protocol] = np.where(n > 0, chi2 / dof, np.nan)
    return out


def locate(observations: Observations, prediction: Prediction, *, n_params: int = 0, alpha: float = 0.05,
           protocols: Sequence[str] | None = None, centre: Sequence[float] = (0.0, 0.0),
           radial_bands: int = 4, sectors: int = 12, regions: RegionProvider | None = None) -> GapLocation:
    """Decompose the noise-normalised residual of ``prediction`` along every axis and test it.

    ``n_params``: parameters fitted to these data (each cell's dof loses its share of them);
    ``alpha``: family-wise level of the cells (Holm over all cells) and level of the global test;
    ``protocols``: restrict to these (None: every predicted protocol); ``centre`` ``(x, y)`` [m]:
    where radii and angles of tracked points are measured from (skin frame: the probe's contact
    point is the origin); ``radial_bands``, ``sectors``: the region partitions (sectors of
    360/``sectors`` degrees, counter-clockwise from +x). ``regions``: the model's partitions of the
    tracked surface instead (:class:`skinkit.schemas.regions.RegionProvider`, e.g.
    :func:`skinkit.forward.region_partitions` of the model description), every one tested as a
    partition of the ``region`` axis; None: the radial bands and sectors around ``centre``.
    """
    if not (0 < alpha < 1):
        raise SchemaError("alpha", f"must be in (0, 1), got {alpha!r}")
    if n_params < 0:
        raise SchemaError("n_params", f"must be >= 0, got {n_params!r}")
    with single_threaded_blas():     # small products: BLAS threads only spin on a shared machine
        return _locate(observations, prediction, n_params, alpha, protocols,
                       _provider(regions, centre, radial_bands, sectors))


def _provider(regions: RegionProvider | None, centre: Sequence[float], radial_bands: int,
              sectors: int) -> RegionProvider:
    """``regions``, else the polar partitions around ``centre``."""
    if regions is not None:
        if not callable(regions):
            raise SchemaError("regions", f"must be a region provider (points -> partitions), got "
                              f"{type(regions).__name__}")
        return regions
    return partial(polar_partitions, centre=centre, radial_bands=radial_bands, sectors=sectors)


def _locate(observations: Observations, prediction: Prediction, n_params: int, alpha: float,
            protocols: Sequence[str] | None, regions: RegionProvider) -> GapLocation:
    ss = samples(observations, prediction, protocols=protocols)
    table = _Table(ss, regions)
    if n_params >= table.N:
        raise SchemaError("n_params", f"{n_params} parameters leave no degree of freedom "
                          f"in {table.N} samples")
    chi2 = float(table.z2.sum())
    dof = float(table.N - n_params)
    nall = np.bincount(table.g, minlength=table.G).astype(float)[None, :]
    scale, ndof = _noise_dof_of(table, nall, 6.0 * nall)
    p, pf = _p_values(np.array([chi2]), np.array([dof]), scale, ndof)
    white, cross = _series_tests(ss, alpha)
    bands = {s.protocol: s.drive.band for s in ss if s.drive is not None}
    cells, whole, family_p = _cells(table, n_params, alpha, (chi2, dof, float(pf[0])))
    # a gap: the whole residual or any cell, one Holm family, so that pure noise raises at most
    # alpha false alarms whichever the reader looks at
    periodic, p_line = _lines(ss, alpha)
    gap = whole or any(c.significant for c in cells) or bool(periodic)
    # the line family is tested at ALPHA_SHARE·alpha: it rejects at any level above p/ALPHA_SHARE
    family_p = min(family_p, p_line / ALPHA_SHARE)
    return GapLocation(chi2, dof, chi2 / dof, float(p[0]), gap, cells, _point_map(ss, n_params, table.N),
                       white, cross, float(ndof[0]), bands, family_p, periodic)


def _lines(ss: list[Samples], alpha: float) -> tuple[list[Line], float]:
    """Periodic components of the tip channels' residuals above ten times their drive's band,
    and the line family's smallest corrected p-value."""
    series = []
    for s in ss:
        if s.raw is None or s.drive is None or s.series_time_s is None:
            continue
        for j, label in enumerate(s.labels):
            name = f"{s.protocol}/{label} {'xyz'[j]}"
            series.append((name, s.full[:, j], s.raw[:, j], s.mask[:, j], s.series_time_s, s.dt,
                           10 * s.drive.band[1], CHANNELS[s.channel][0]))
    return search(series, alpha)


def cell_chi2(observations: Observations, prediction: Prediction, cells: Sequence[tuple[str, str]],
              protocols: Sequence[str] | None = None, *, n_params: int = 0,
              centre: Sequence[float] = (0.0, 0.0), radial_bands: int = 4,
              sectors: int = 12, regions: RegionProvider | None = None
              ) -> dict[tuple[str, str], tuple[float, float]]:
    """``(axis, label) -> (chi2, dof)`` of ``prediction`` over the same cells as :func:`locate`
    with the same region arguments (for "before/after" comparisons); a cell absent here gives
    ``(0.0, 0.0)``."""
    for a, _ in cells:
        if a not in AXES:
            raise SchemaError("cells", f"unknown axis {a!r} (one of {list(AXES)})")
    ss = samples(observations, prediction, protocols=protocols)
    table = _Table(ss, _provider(regions, centre, radial_bands, sectors))
    got: dict[tuple[str, str], tuple[float, float]] = {}
    for part in table.partitions():
        n = part.nmat.sum(axis=1)
        for lab, c2, nn in zip(part.labels, part.chi2, n, strict=True):
            if nn > 0:
                got[(part.axis, lab)] = (float(c2), float(nn - n_params * nn / table.N))
    return {tuple(c): got.get(tuple(c), (0.0, 0.0)) for c in cells}


__all__ = ["AXES", "BANDS", "CYCLES", "PHASES", "Cell", "Drive", "GapLocation", "Samples", "cell_chi2",
           "holm", "holm_adjusted", "locate", "make_drive", "noise_dof", "samples"]
