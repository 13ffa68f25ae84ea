"""Measured against predicted over time, compact enough to ride in a report's JSON.

:func:`compact_series` keeps, per protocol and channel, the measured samples and one or more
models' predictions on at most :data:`MAX_SAMPLES` times (every k-th sample: peaks may fall
between, but nothing is smoothed or invented). A tip channel keeps its three components; a
tracked-point channel keeps the mean displacement of its points from their reference positions,
per component, over the points both measured and predicted at that frame (a whole field of
points would not fit; its spatial detail is in the residual maps).

The shape (JSON-ready; NaN, a sample not measured or not predicted, becomes null in the JSON)::

    {protocol: {"held_out": bool,
                "channels": {channel: {"unit": "N", "quantity": "tip force",
                                       "components": ["x", "y", "z"],
                                       "time_s": [n],
                                       "measured": [[n] per component],
                                       "predicted": {model label: [[n] per component]}}}}}
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from skinkit.schemas import Channel, ChannelPrediction, Observations, Prediction

#: the most samples kept per channel
MAX_SAMPLES = 500
#: what each channel's kept series is, for a figure's axis label
QUANTITY = {"tip_force": "tip force", "tip_position": "tip position",
            "points": "mean displacement of the tracked points",
            "points_2d": "mean in-plane displacement of the tracked points"}


def decimation(n: int, max_samples: int = MAX_SAMPLES) -> np.ndarray:
    """Indices of at most ``max_samples`` of ``n`` samples, evenly spread, first and last kept."""
    if n <= max_samples:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max_samples).round().astype(int))


def _rounded(a: np.ndarray) -> list[list[float]]:
    """``(n, k)`` as k lists of n floats, 6 significant digits (the JSON stays small)."""
    return [[float(f"{v:.6g}") for v in col] for col in np.asarray(a, float).T]


def _point_means(ch: Channel, values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``(T, k)`` mean over the points of ``values - reference`` on ``mask`` ``(P, T, k)`` [m]
    (NaN at a frame with no point)."""
    k = ch.values.shape[-1]
    ref = ch.reference[:, :k] if ch.reference is not None else ch.values[:, 0, :]
    d = np.where(mask, np.asarray(values, float) - ref[:, None, :], 0.0)
    n = mask.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, d.sum(axis=0) / np.maximum(n, 1), np.nan)


def _channel(ch: Channel, preds: Mapping[str, ChannelPrediction]) -> dict[str, Any] | None:
    """One channel's compact series (module docstring); None when no model predicts it."""
    if not preds:
        return None
    masks = {lab: ch.valid if cp.predicted is None else ch.valid & np.asarray(cp.predicted, bool)
             for lab, cp in preds.items()}
    if ch.is_points:
        common = np.logical_and.reduce(list(masks.values()))   # the same points on both sides
        measured = _point_means(ch, ch.values, common)
        predicted = {lab: _point_means(ch, cp.values, common) for lab, cp in preds.items()}
    else:
        measured = np.where(ch.valid, ch.values, np.nan)
        predicted = {lab: np.where(masks[lab], cp.values, np.nan) for lab, cp in preds.items()}
    keep = decimation(ch.time_s.size)
    comps = list("xyz"[: measured.shape[1]])
    return {"unit": ch.unit, "quantity": QUANTITY.get(ch.name, ch.name), "components": comps,
            "time_s": [float(f"{t:.6g}") for t in ch.time_s[keep]],
            "measured": _rounded(measured[keep]),
            "predicted": {lab: _rounded(p[keep]) for lab, p in predicted.items()}}


def compact_series(observations: Observations, predictions: Mapping[str, Prediction]
                   ) -> dict[str, dict[str, Any]]:
    """Per protocol and channel the measured and predicted series (module docstring).

    ``predictions``: model label (e.g. ``"calibrated"``, ``"with the named effects"``) ->
    that model's prediction of ``observations``. A channel no model predicts (the drive input)
    is left out, and a protocol with no channel left."""
    out: dict[str, dict[str, Any]] = {}
    for po in observations:
        chans: dict[str, Any] = {}
        for name, ch in po.channels.items():
            preds = {lab: p.protocols[po.name][name] for lab, p in predictions.items()
                     if name in p.protocols.get(po.name, {})}
            entry = _channel(ch, preds)
            if entry is not None:
                chans[name] = entry
        if chans:
            out[po.name] = {"held_out": bool(po.held_out), "channels": chans}
    return out


def diagnosis_series(observations: Observations, first: Mapping[str, Any], final: Mapping[str, Any],
                     additions: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """The compact series of a gap diagnosis: the calibrated model's prediction (``first``, a
    state with its ``"prediction"``) and, when effects were added (``additions``, each with its
    ``"effect"``), the final model's, labelled by what was added."""
    preds = {"calibrated": first["prediction"]}
    if additions and final is not first:
        preds["with " + ", ".join(str(a["effect"]) for a in additions)] = final["prediction"]
    return compact_series(observations, preds)


__all__ = ["MAX_SAMPLES", "QUANTITY", "compact_series", "decimation", "diagnosis_series"]
