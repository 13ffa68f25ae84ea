"""``skinkit bench fit``: skinkit's analytic-Jacobian fit against the ways peers fit, same problem and start.

The problem: a layered disc (QLV skin over neo-Hookean tissue, ~1,000 unknowns) driven by the
recorded tip force of two 0.1 Hz protocols (normal and oblique, 100 Hz robot record, 36
tracked points at 1 Hz), a virtual session made from known parameters plus Gaussian noise at
the robot's and the cameras' levels on the predicted channels (the force drive exact). Four
parameters are fitted (skin μ, tissue E, g1, τ1) from the same start (each 30-60 % off):

* **skinkit**: trust-region least squares fed the forward model's analytic sensitivities;
* **finite differences**: the same least squares, the optimiser differencing the residual
  (p + 1 solves per Jacobian: FEBio's levmar, GIBBON's lsqnonlin);
* **derivative-free**: NLopt BOBYQA on ½‖z‖² (Lavigne et al. used NLopt CRS2).

Cost is counted in forward-solve equivalents: a prediction with sensitivities counts as its
measured time over that of a plain prediction, at the truth.
"""

from __future__ import annotations

import copy
import time
from typing import Any

import numpy as np

from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

SPEC: dict[str, Any] = {
    "model": {"name": "bench-fit"},
    "geometry": {"kind": "disc", "diameter": "20 mm", "indenter_diameter": "4 mm", "n_inner": 2, "n_ring": 2},
    "layers": [
        {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "qlv",
         "options": {"elastic": "neo-hookean-ni", "terms": 1},
         "parameters": {"mu": "15 kPa", "K": "500 kPa", "g1": 0.3, "tau1": "2 s"}},
        {"name": "subdermal", "thickness": "3.5 mm", "elements": 1, "law": "neo-hookean-enu",
         "parameters": {"E": "10 kPa", "nu": 0.45}},
    ],
    "indenter": {"mode": "force"},
    "drive": {"max_step": "0.5 s"},
}
FREE = ("skin.mu", "subdermal.E", "skin.g1", "skin.tau1")
START = {"skin.mu": 22e3, "subdermal.E": 6e3, "skin.g1": 0.15, "skin.tau1": 4.0}
NOISE = {"tip_force": 1.7e-3, "tip_position": 1.7e-6, "points": 4e-6}


def bench_session(model: Any, seed: int = 0) -> Observations:
    """The virtual session of the module docstring, from ``model`` at its own parameters."""
    T = np.arange(0, 10.0001, 0.01)
    s = 0.5 * (1 - np.cos(2 * np.pi * 0.1 * T))
    th = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    ref = np.array([[r * np.cos(a), r * np.sin(a), 0.0] for r in (3e-3, 5e-3, 7e-3) for a in th])
    tf = np.arange(0, 10.0001, 1.0)
    skel = {}
    for name, d in (("normal", (0, 0, -1)), ("oblique", (0.4, 0.2, -1))):
        F = 0.03 * s[:, None] * np.asarray(d, float)
        chans = {"tip_force": Channel("tip_force", T, F, noise=NOISE["tip_force"]),
                 "tip_position": Channel("tip_position", T, 0 * F, noise=NOISE["tip_position"]),
                 "points": Channel("points", tf, np.repeat(ref[:, None], tf.size, 1), noise=NOISE["points"],
                                   reference=ref)}
        skel[name] = ProtocolObservations(Protocol(name), chans)
    obs = Observations(skel, None, "bench")
    pred = model.predict(model.parameters(), obs)
    rng = np.random.default_rng(seed)
    out = {}
    for po in obs:
        ch = dict(po.channels)
        for c, cp in pred.protocols[po.name].items():
            o = ch[c]
            noisy = cp.values + o.noise * rng.standard_normal(cp.values.shape)
            ch[c] = Channel(c, o.time_s, noisy, noise=o.noise, reference=o.reference)
        # the drive is the programmed force itself: noise on a force drive is an
        # errors-in-variables problem that biases every method alike (by 7-15 standard errors
        # here), which would make "equal accuracy" meaningless (docs/guide/identification.md)
        out[po.name] = ProtocolObservations(po.protocol, ch)
    return Observations(out, None, "bench")


def _cost_ratio(model: Any, obs: Observations, repeats: int = 5) -> float:
    """Time of a prediction with sensitivities to the free parameters over a plain one: the
    least of ``repeats`` timings of each, taken in alternation so that a change in the
    machine's other load (which only ever adds time) reaches both alike."""
    p = model.parameters()
    plain, sens = [], []
    for _ in range(repeats):
        for kw, times in (({}, plain), ({"sensitivities": list(FREE)}, sens)):
            t0 = time.perf_counter()
            model.predict(p, obs, **kw)
            times.append(time.perf_counter() - t0)
    return min(sens) / min(plain)


def run(seed: int = 0) -> dict[str, Any]:
    """Every method from the same start; JSON-ready figures."""
    from skinkit.forward import load
    from skinkit.inverse import fit

    model = load(copy.deepcopy(SPEC), workers=1)
    truth = {n: model.parameters()[n] for n in FREE}
    obs = bench_session(model, seed)
    ratio = _cost_ratio(model, obs)
    out: dict[str, Any] = {"n_params": len(FREE), "sensitivity_cost_ratio": ratio, "truth": truth,
                           "start": START}
    runs = {"skinkit": {"jacobian": "analytic"},
            "fd": {"jacobian": "fd"},
            "dfo": {"jacobian": "none", "optimiser": "nlopt-bobyqa", "max_iterations": 400, "ftol": 1e-8,
                    "xtol": 1e-6}}
    for label, kw in runs.items():
        t0 = time.perf_counter()
        r = fit(model, obs, list(FREE), start=dict(START), **kw)
        wall = time.perf_counter() - t0
        est = {n: r.parameters[n] for n in FREE}
        err = max(abs(est[n] - truth[n]) / abs(truth[n]) for n in FREE)
        equiv = (r.n_forward - r.n_sensitivity) + r.n_sensitivity * ratio
        out[f"{label}_forward_equivalents"] = float(equiv)
        out[f"{label}_forward_solves"] = int(r.n_forward)
        out[f"{label}_param_error"] = float(err)
        out[f"{label}_wall_s"] = wall
        out[f"{label}_parameters"] = est
        out[f"{label}_converged"] = bool(r.converged)
        if label == "skinkit":
            out["skinkit_se"] = r.se
    out["fd_over_skinkit"] = out["fd_forward_equivalents"] / out["skinkit_forward_equivalents"]
    out["dfo_over_skinkit"] = out["dfo_forward_equivalents"] / out["skinkit_forward_equivalents"]
    return out


def summary_lines(res: dict[str, Any]) -> list[str]:
    """The figures of :func:`run` as lines of text."""
    out = [f"{res['n_params']} parameters; a prediction with sensitivities costs "
           f"{res['sensitivity_cost_ratio']:.2f} plain predictions"]
    for label, title in (("skinkit", "skinkit (analytic)"), ("fd", "finite differences"), ("dfo", "BOBYQA")):
        out.append(f"  {title:22s} {res[f'{label}_forward_equivalents']:7.1f} forward-solve equivalents "
                   f"({res[f'{label}_forward_solves']} solves), {res[f'{label}_wall_s']:7.1f} s, "
                   f"largest parameter error {100 * res[f'{label}_param_error']:.2f} %")
    out.append(f"  finite differences need {res['fd_over_skinkit']:.1f}x, "
               f"BOBYQA {res['dfo_over_skinkit']:.1f}x the forward-solve equivalents of skinkit")
    return out
