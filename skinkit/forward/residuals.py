"""How far a prediction is from the observations, per protocol and channel.

The residual of a sample is ``prediction − observation``; normalised by the channel's noise
(and, for tracked points whose reference is a measured frame, decorrelated along frames,
:meth:`skinkit.schemas.Channel.whiten`)
(standard deviation of one sample) it is a standard normal variable when the model is
right and the noise estimate honest, so Σ r² over n samples follows a χ² distribution with
n degrees of freedom: χ²/n is 1 ± √(2/n).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from skinkit.errors import ForwardError
from skinkit.schemas import Observations, Prediction


def chi2_range(n: int, p: float = 0.999) -> tuple[float, float]:
    """The central ``p`` interval of χ²/n for ``n`` degrees of freedom."""
    from scipy.stats import chi2

    if n <= 0:
        return float("nan"), float("nan")
    a = (1 - p) / 2
    return float(chi2.ppf(a, n) / n), float(chi2.ppf(1 - a, n) / n)


def summarise(prediction: Prediction, observations: Observations) -> dict[str, Any]:
    """Per protocol and channel: samples, χ², χ²/n, RMS residual [unit], noise [unit], and
    the overall χ²/n with its 99.9 % range under the noise alone. JSON-ready."""
    out: dict[str, Any] = {"protocols": {}}
    tot, n_tot = 0.0, 0
    for proto, cname, cp in prediction.items():
        ch = observations[proto].channels[cname]
        m = cp.mask(ch)
        r = np.where(m, cp.values - np.where(m, ch.values, 0.0), 0.0)
        z = ch.normalised(cp.values, m)
        n = int(m.sum())
        with np.errstate(over="ignore", invalid="ignore"):
            c2 = float(np.sum(z[m] ** 2))
        if not np.isfinite(c2):   # an inf chi2 would read as a prediction that ran
            raise ForwardError(f"protocol {proto!r} {cname}", "the residual's sum of squares is not a finite "
                               "number: the prediction is not finite, or too far from the record to be "
                               "compared with it (a parameter value far outside the record's range?)")
        lead = tuple(range(r.ndim - 1))
        rms = np.sqrt(np.sum(r ** 2, axis=lead) / np.maximum(m.sum(axis=lead), 1))
        out["protocols"].setdefault(proto, {})[cname] = {
            "samples": n, "chi2": c2, "chi2_per_sample": c2 / n if n else float("nan"),
            "rms": rms.tolist(), "noise": ch.noise.tolist(), "unit": ch.unit,
            "noise_source": ch.noise_source, "held_out": observations[proto].held_out}
        tot += c2
        n_tot += n
    lo, hi = chi2_range(n_tot)
    out["chi2"] = tot
    out["samples"] = n_tot
    out["chi2_per_sample"] = tot / n_tot if n_tot else float("nan")
    out["noise_only_range_999"] = [lo, hi]
    out["consistent_with_noise"] = bool(lo <= out["chi2_per_sample"] <= hi) if n_tot else False
    return out


__all__ = ["chi2_range", "summarise"]
