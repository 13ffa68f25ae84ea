"""How well the carried model error matches a truth the model did not make.

The approximation-error approach (:mod:`skinkit.inverse.approximation`) estimates the model's
discretisation error from the model's own mesh refined uniformly 2x: its mean m = R̄ d with d =
fine − model and R̄ the Richardson factor for an order between 1 and 2, and a covariance for the
order's uncertainty. Whether that describes the error against a *different* discretisation — the
virtual lab's truth on a mesh of its own, finer and with its own node placement
(:mod:`skinkit.lab.truth_mesh`) — is a claim this check measures, at the truth's parameters and
without noise (so that every figure is the error model's, not a draw's):

* per protocol and channel: the RMS of e = truth − model, of d (the estimate's, averaged over its
  draws around the truth's parameters), and of the miss e − m, in noise levels; the ratio
  a = ⟨d, e⟩ / ⟨d, d⟩ that would fit e best along d, against the range
  [R(2), R(1)] the estimate assumes for an exact solution; and **χ²/n of the miss under the
  carried covariance** (noise plus model error): the excess per sample a noiseless null session
  would show, which a correct error model keeps near 0;
* for tracked points, the same ratio per point and component (its 10th, 50th and 90th
  percentiles) and per radial band of the points' distance from the probe: a single ratio per
  band is what the estimate's covariance allows.

* **the draws' linearity**: the estimate moves the refined-minus-model difference to its draw
  around the parameters by the difference's derivatives instead of solving both meshes there
  (:func:`skinkit.inverse.approximation.estimate`); the check solves the draw as well and reports
  ‖W(d_solved − d_moved)‖ / ‖W(d_solved − d_0)‖, the share of the draw's change that the first
  order misses.

A truth finer than the model is not exact: its own error (the truth file's bound) limits what the
check can tell apart, and ``truth_factor`` makes it finer.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError

#: radial bands of tracked points reported
BANDS = 4


def _ratio(d: np.ndarray, e: np.ndarray) -> float | None:
    den = float((d * d).sum())
    return float((d * e).sum()) / den if den > 0 else None


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(a ** 2))) if a.size else float("nan")


def _points(d: np.ndarray, e: np.ndarray, ref: np.ndarray) -> dict[str, Any]:
    """Per point and component ratios (percentiles) and per radial band, of ``d`` and ``e``
    ``(P, F, C)`` in noise units; ``ref`` ``(P, 3)`` [m]."""
    den = (d * d).sum(axis=1)
    per = np.where(den > 0, (d * e).sum(axis=1) / np.maximum(den, 1e-300), np.nan)[den > 1.0]
    rad = np.hypot(ref[:, 0], ref[:, 1])
    order = np.argsort(rad)
    bands = []
    for b in np.array_split(order, BANDS):
        if b.size:
            bands.append({"r_mm": [float(1e3 * rad[b].min()), float(1e3 * rad[b].max())],
                          "ratio": _ratio(d[b], e[b]), "rms_error": _rms(e[b]), "rms_refined": _rms(d[b])})
    q = np.quantile(per, [0.1, 0.5, 0.9]).tolist() if per.size else None
    return {"ratio_per_point": {"p10": q[0], "p50": q[1], "p90": q[2]} if q else None, "bands": bands}


def run_case(case: str, truth_factor: int = 2, workers: int | None = 1,
             say: Callable[[str], None] | None = None) -> dict[str, Any]:
    """The check on :mod:`skinkit.bench.coverage`'s finite-element ``case`` with its truth
    ``truth_factor`` times finer (module); JSON-ready."""
    from skinkit.bench.coverage import SPECS
    from skinkit.forward import load, model_kind
    from skinkit.inverse.approximation import ORDER_HIGH, ORDER_LOW, estimate
    from skinkit.inverse.coverage import LabSessions
    from skinkit.inverse.discretisation import DEFAULT_FACTOR, richardson_factor
    from skinkit.inverse.objective import Objective
    from skinkit.schemas import Observations, Prediction

    if case not in SPECS:
        raise SkinkitError(f"--case: unknown case {case!r}; choose from {', '.join(SPECS)}")
    spec, free = SPECS[case]()
    if model_kind(spec) != "fe":
        raise SkinkitError(f"--case {case}: a lumped model has no mesh to check")
    tell = say or (lambda _m: None)
    t0 = time.perf_counter()
    tell(f"{case}: the truth on its own mesh ({truth_factor}x)")
    lab = LabSessions(spec, workers=workers, mesh="own", mesh_factor=truth_factor)
    obs = lab.noiseless().fitted()
    model = load(lab.model_spec, workers=workers)
    try:
        params = model.parameters()
        tell(f"{case}: the model's error estimated at the truth's parameters (its mesh and one refined 2x)")
        err = estimate(model, obs, params, free)
        tell(f"{case}: its draw solved on both meshes as well, to measure the first order's miss")
        linearity = draw_linearity(estimate(model, obs, params, free, solve_draws=True), err, obs)
        pred = model.predict(params, obs, sensitivities=False)
    finally:
        model.close()
    r_lo, r_hi = richardson_factor(DEFAULT_FACTOR, ORDER_HIGH), richardson_factor(DEFAULT_FACTOR, ORDER_LOW)
    r_mid = 0.5 * (r_lo + r_hi)
    carried = obs.with_model_error(err)
    rows = []
    for proto, cname, cp in pred.items():
        key = (proto, cname)
        if key not in err.mean:
            continue
        ch = obs[proto].channels[cname]
        m = cp.mask(ch)
        sig = np.broadcast_to(ch.sigma(), ch.values.shape)
        e = np.where(m, (np.nan_to_num(ch.values) - cp.values) / sig, 0.0)
        d = np.where(m, err.mean[key] / r_mid / sig, 0.0)
        miss = e - r_mid * d
        po = type(obs[proto])(obs[proto].protocol, {cname: ch})
        one = Observations({proto: po}, obs.profile, obs.source, carried.model_error)
        res = Objective(None, one, [], "noise").residual(Prediction({proto: {cname: cp}}), jacobian=False)
        row = {"protocol": proto, "channel": cname, "samples": int(m.sum()),
               "rms_error": _rms(e[m]), "rms_refined": _rms(d[m]), "rms_miss": _rms(miss[m]),
               "ratio": _ratio(d, e), "chi2_per_sample": float(res.z @ res.z) / max(int(res.z.size), 1)}
        if ch.is_points and ch.reference is not None:
            row.update(_points(d, e, np.asarray(ch.reference, float)))
        rows.append(row)
    mesh = lab.truth.truth.get("mesh") or {}
    return {"case": case, "truth_factor": truth_factor, "truth_mesh": mesh,
            "ratio_range": [r_lo, r_hi], "ratio_assumed": r_mid, "channels": rows,
            "model_error": err.summary, "draw_linearity": linearity, "wall_s": time.perf_counter() - t0}


def draw_linearity(solved: Any, moved: Any, obs: Any) -> float | None:
    """‖W(d_solved − d_moved)‖ / ‖W(d_solved − d_0)‖ over the draws of two estimates made at one
    point with one seed, the draws of ``solved`` solved on both meshes and those of ``moved``
    moved to by the derivatives (W: the noise's whitening); None when either kept no draws."""
    from skinkit.inverse.approximation import noise_weights

    if solved.source is None or moved.source is None or len(solved.source.diffs) < 2:
        return None
    d0 = solved.source.diffs[0]
    num = den = 0.0
    for ds, dm in zip(solved.source.diffs[1:], moved.source.diffs[1:], strict=True):
        for key, d in ds.items():
            w = noise_weights(obs[key[0]].channels[key[1]])
            num += float(np.sum((w * (d - dm[key])) ** 2))
            den += float(np.sum((w * (d - d0[key])) ** 2))
    return float(np.sqrt(num / den)) if den > 0 else None


def run(cases: list[str], truth_factor: int = 2, say: Callable[[str], None] | None = None) -> dict[str, Any]:
    """:func:`run_case` for each of ``cases``: ``{"cases": {name: ...}, "truth_factor", "wall_s"}``."""
    t0 = time.perf_counter()
    out = {c: run_case(c, truth_factor, say=say) for c in cases}
    return {"cases": out, "truth_factor": truth_factor, "wall_s": time.perf_counter() - t0}


def summary_lines(res: dict[str, Any]) -> list[str]:
    """The figures of :func:`run` as lines of text."""
    from skinkit.lab.truth_mesh import largest_truth_error

    out = []
    for name, c in res["cases"].items():
        tm = c.get("truth_mesh") or {}
        own = largest_truth_error(tm)
        lo, hi = c["ratio_range"]
        bound = "-" if own is None else f"{own:.3g}"
        out.append(f"{name}: truth {tm.get('truth_unknowns', 0):,} unknowns ({c['truth_factor']}x, its own "
                   f"error at most {bound} noise levels), model {tm.get('model_unknowns', 0):,}; "
                   f"ratio assumed {c['ratio_assumed']:.3f} in [{lo:.3f}, {hi:.3f}]")
        out.append("  protocol              channel     RMS truth-model  RMS refined  ratio  RMS miss  "
                   "chi2/n carried")
        for r in c["channels"]:
            ratio = "-" if r["ratio"] is None else f"{r['ratio']:.3f}"
            out.append(f"  {r['protocol'][:20]:20s}  {r['channel']:10s}  {r['rms_error']:15.3g}  "
                       f"{r['rms_refined']:11.3g}  {ratio:>5s}  {r['rms_miss']:8.3g}  "
                       f"{r['chi2_per_sample']:14.3g}")
            pp = r.get("ratio_per_point")
            if pp:
                out.append(f"    ratio per point and component: 10 % {pp['p10']:.2f}, median "
                           f"{pp['p50']:.2f}, 90 % {pp['p90']:.2f}")
                bands = [f"{b['r_mm'][0]:.1f}-{b['r_mm'][1]:.1f} mm "
                         f"{'-' if b['ratio'] is None else format(b['ratio'], '.2f')}"
                         for b in r.get("bands", [])]
                out.append("    by distance from the probe: " + "; ".join(bands))
    out.append("RMS in noise levels; ratio: (truth - model) along (refined - model); chi2/n: the miss under "
               "the carried covariance per sample, what a noiseless null would show beyond the noise")
    return out


__all__ = ["BANDS", "draw_linearity", "run", "run_case", "summary_lines"]
