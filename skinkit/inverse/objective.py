"""The weighted residual of a forward model against a session (thesis Eq 7.12): z = W (y(θ) − Y).

Weightings, by name:

* ``noise`` (default): every sample divided by its channel's noise level, so newtons and
  metres are commensurate and Σz² is a χ² under the noise model;
* ``unweighted``: z = y − Y in SI units (only meaningful for one kind of channel);
* ``displacement``: as ``noise``, and each tracked point further weighted by its largest
  measured displacement over the largest of any point (the thesis's choice, Ch 7);
* ``threshold``: as ``noise``, keeping only points whose largest displacement exceeds
  ``threshold`` [m] (Ch 6; default five times the points' noise);
* ``robot-only``: tip force and tip position only (the thesis's comparison, 7.6.1);
* ``strain``: as ``noise``, each point further weighted by the largest local surface strain
  near it (its displacement relative to its six nearest neighbours' over their distance),
  over the largest of any point (the thesis's future work).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.errors import SchemaError
from skinkit.schemas import Channel, Observations, ParameterSet, Prediction

WEIGHTINGS = ("noise", "unweighted", "displacement", "threshold", "robot-only", "strain")


def _point_scale(ch: Channel, weighting: str, threshold: float | None) -> np.ndarray | None:
    """``(P,)`` extra per-point factor of a point channel (None: 1)."""
    disp = np.where(ch.valid, ch.values - ch.values[:, :1], np.nan)
    dmax = np.nanmax(np.linalg.norm(disp, axis=-1), axis=1)
    dmax = np.nan_to_num(dmax)
    if weighting == "displacement":
        top = dmax.max()
        return dmax / top if top > 0 else np.ones_like(dmax)
    if weighting == "threshold":
        thr = 5 * float(np.max(ch.noise)) if threshold is None else threshold
        return (dmax > thr).astype(float)
    if weighting == "strain":
        from scipy.spatial import cKDTree
        ref = ch.reference if ch.reference is not None else np.nan_to_num(ch.values[:, 0])
        k = min(6, len(ref) - 1)
        if k < 1:
            return np.ones(len(ref))
        dist, nb = cKDTree(ref[:, : ch.values.shape[-1]]).query(ref[:, : ch.values.shape[-1]], k + 1)
        rel = np.nan_to_num(disp[:, None] - disp[nb[:, 1:]])          # (P, k, F, c)
        strain = np.linalg.norm(rel, axis=-1) / np.maximum(dist[:, 1:, None], 1e-12)
        s = np.nanmax(strain.reshape(len(ref), -1), axis=1)
        top = s.max()
        return s / top if top > 0 else np.ones_like(s)
    return None


@dataclass
class Residual:
    """A stacked residual: ``z`` ``(m,)``, ``J`` ``(m, n)`` (∂z/∂p in SI per parameter, or None),
    and for each block its protocol, channel and slice (for per-protocol and per-channel sums)."""

    z: np.ndarray
    J: np.ndarray | None
    blocks: list[tuple[str, str, slice]] = field(default_factory=list)

    def by(self, what: str = "protocol") -> dict[str, float]:
        """Σz² per protocol (``what="protocol"``) or per channel."""
        out: dict[str, float] = {}
        for p, c, sl in self.blocks:
            key = p if what == "protocol" else c
            out[key] = out.get(key, 0.0) + float(np.sum(self.z[sl] ** 2))
        return out


class Objective:
    """z(θ) for ``model`` on ``observations`` with respect to the parameters ``names``.

    ``weighting``: one of :data:`WEIGHTINGS`; ``threshold`` [m] for ``"threshold"``.
    Every evaluation is one forward prediction; with ``jacobian=True`` its sensitivities
    to ``names`` come with it (analytic where the model offers them).
    """

    def __init__(self, model: Any, observations: Observations, names: Sequence[str],
                 weighting: str = "noise", threshold: float | None = None) -> None:
        if weighting not in WEIGHTINGS:
            raise SchemaError("--objective", f"must be one of {list(WEIGHTINGS)}, got {weighting!r}")
        if not len(observations):
            raise SchemaError("session", "has no protocol to fit")
        self.model = model
        self.observations = observations
        self.names = list(names)
        self.weighting = weighting
        self.threshold = threshold
        self.n_forward = 0
        self.n_sensitivity = 0
        self._scales: dict[tuple[str, str], np.ndarray | None] = {}

    def weights(self, proto: str, cname: str, ch: Channel) -> tuple[np.ndarray, np.ndarray]:
        """``(weight, keep)`` arrays of channel ``ch``'s shape (protocol ``proto``, name ``cname``):
        each entry's weight in the residual [1/unit] and whether it enters at all."""
        if self.weighting == "robot-only" and ch.is_points:
            return np.zeros(ch.values.shape), np.zeros(ch.values.shape, bool)
        w = np.ones(ch.values.shape) if self.weighting == "unweighted" else \
            1.0 / ch.sigma()
        if ch.is_points and self.weighting in ("displacement", "threshold", "strain"):
            key = (proto, cname)
            if key not in self._scales:
                self._scales[key] = _point_scale(ch, self.weighting, self.threshold)
            s = self._scales[key]
            if s is not None:
                w = w * s[:, None, None]
        return w, w != 0

    def residual(self, prediction: Prediction, jacobian: bool = True) -> Residual:
        """The stacked weighted residual of ``prediction``."""
        zs, Js, Vs, blocks = [], [], [], []
        start = 0
        err = self.observations.model_error
        for proto, cname, cp in prediction.items():
            ch = self.observations[proto].channels[cname]
            w, keep = self.weights(proto, cname, ch)
            m = cp.mask(ch) & keep
            if not m.any():
                continue
            values = cp.values
            if err is not None and (proto, cname) in err.mean:   # the model's mean error added
                values = values + err.mean[(proto, cname)]
            # a measured reference frame correlates a point's residuals: whiten along frames
            full = ch.whiten(np.where(m, (values - np.where(m, ch.values, 0.0)) * w, 0.0), m)
            r = full[m]
            zs.append(r)
            if jacobian:
                cols = [ch.whiten(np.where(m, cp.d[n] * w, 0.0), m)[m] for n in self.names]
                Js.append(np.stack(cols, axis=1) if cols else np.zeros((r.size, 0)))
            if err is not None and err.rank:
                b = err.basis.get((proto, cname))
                Vs.append(np.zeros((r.size, err.rank)) if b is None else
                          np.stack([ch.whiten(np.where(m, bj * w, 0.0), m)[m] for bj in b], axis=1))
            blocks.append((proto, cname, slice(start, start + r.size)))
            start += r.size
        if not zs:
            raise SchemaError("session", f"no observed channel is predicted with the {self.weighting!r} "
                              "weighting (does the session have the channels the model predicts?)")
        z, J = np.concatenate(zs), (np.concatenate(Js) if jacobian else None)
        if Vs:   # noise plus the model error's covariance, whitened (approximation.whitening)
            from skinkit.inverse.lowrank import apply, whitening

            Q, shrink = whitening(np.concatenate(Vs))
            z = apply(Q, shrink, z)
            J = None if J is None else apply(Q, shrink, J)
        return Residual(z, J, blocks)

    def evaluate(self, params: ParameterSet, jacobian: bool = True) -> tuple[Residual, Prediction]:
        """One forward prediction at ``params`` and its residual."""
        pred = self.model.predict(params, self.observations, sensitivities=self.names if jacobian else False)
        self.n_forward += 1
        if jacobian and self.names:
            self.n_sensitivity += 1
        return self.residual(pred, jacobian), pred


def held_out_rms(model: Any, params: ParameterSet, observations: Observations,
                 weighting: str = "noise") -> dict[str, float]:
    """RMS of the weighted residual per held-out protocol (noise-normalised by default)."""
    ho = observations.held_out()
    if not len(ho):
        return {}
    obj = Objective(model, ho, [], weighting)
    res, _ = obj.evaluate(params, jacobian=False)
    out = {}
    for p, _, sl in res.blocks:
        out.setdefault(p, []).append(res.z[sl])
    return {p: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for p, v in out.items()}


__all__ = ["WEIGHTINGS", "Objective", "Residual", "held_out_rms"]

