"""``skinkit bench fit-invivo``: the in vivo scale of identification.

Four GOH + QLV parameters of the layered in vivo model (``docs/models/invivo_goh_qlv.toml``,
about 10,000 unknowns) identified from the 16 protocols of thesis Table 12 (normal indentation,
in-plane stretch every 30 degrees, three out-of-plane directions), each the 1.5 mm p-p 0.1 Hz
sinusoid for three periods, on a virtual session: the lab's truth solved once, Gaussian noise at
the lab's levels (the coverage study's sessions, ``skinkit.inverse.coverage.LabSessions``).
The fit starts 10 % off the truth (c, k1, κ, g1). Reported: the wall time of the fit on this
machine, its forward solves, and where the time goes (assembly against linear solves, Newton
iterations per step, from one prediction with sensitivities at the optimum).
"""

from __future__ import annotations

import time
from typing import Any

from skinkit.examples import example_model

TABLE12 = ("normal_indentation", *(f"in_plane_{a:03d}" for a in range(0, 360, 30)),
           "out_of_plane_330", "out_of_plane_285", "out_of_plane_240")
FREE = ("skin.c", "skin.k1", "skin.kappa", "skin.g1")


def spec(n_protocols: int = 16, periods: int = 3) -> dict[str, Any]:
    """The in vivo truth with its Table 12 session (the first ``n_protocols``)."""
    from skinkit.fem.discretisation import pin_mesh
    from skinkit.fem.model import read_model

    # the benchmark's mesh (9,747 unknowns: the ~10,000 unknowns of an in vivo fit), not the example file's
    s = pin_mesh(read_model(example_model("invivo_goh_qlv")), [2, 2], n_inner=3, n_ring=3, grading=1.6)
    s.pop("load", None)
    protos = list(TABLE12[:n_protocols])
    s["session"] = {"protocols": protos, "parameters": {p: {"periods": periods} for p in protos}}
    s.setdefault("surface", {})["fit"] = False
    s.setdefault("drive", {})["max_step"] = "0.5 s"
    return s


def run(n_protocols: int = 16, periods: int = 3, workers: int = 2, seed: int = 0,
        log: Any = None) -> dict[str, Any]:
    """Generate the session, fit, and time it; JSON-ready figures."""
    import numpy as np

    from skinkit.forward import load
    from skinkit.inverse import fit
    from skinkit.inverse.coverage import LabSessions

    t0 = time.perf_counter()
    lab = LabSessions(spec(n_protocols, periods), workers=workers, mesh="shared")
    obs = lab(seed)
    t_lab = time.perf_counter() - t0
    model = load(lab.model_spec, workers=workers)
    try:
        truth = {n: model.parameters()[n] for n in FREE}
        start = {n: v * (1.1 if i % 2 == 0 else 0.9) for i, (n, v) in enumerate(truth.items())}

        def progress(i: int, phi: float, x: dict[str, float]) -> None:
            if log is not None:
                vals = ", ".join(f"{k} = {v:.4g}" for k, v in x.items())
                print(f"  evaluation {i} ({time.perf_counter() - t1:.0f} s): objective {phi:.6g} [{vals}]",
                      file=log, flush=True)

        t1 = time.perf_counter()
        r = fit(model, obs, list(FREE), start=start, progress=progress)
        wall = time.perf_counter() - t1
        t2 = time.perf_counter()
        pred = model.predict(r.parameters, obs.fitted(), sensitivities=list(FREE))
        one = time.perf_counter() - t2
        protos = pred.info.get("protocols", {})
        assembly = float(sum(p.get("assembly_s", 0.0) for p in protos.values()))
        solve = float(sum(p.get("linear_solve_s", 0.0) for p in protos.values()))
        n_dof = int(next(iter(protos.values())).get("n_dof", 0)) if protos else 0
        newton = (float(np.mean([p.get("newton_per_step", np.nan) for p in protos.values()]))
                  if protos else None)
    finally:
        model.close()
    est = {n: r.parameters[n] for n in FREE}
    return {"n_protocols": n_protocols, "periods": periods, "n_dof": n_dof, "workers": workers,
            "n_params": len(FREE), "wall_s_fit": wall, "wall_s_session": t_lab,
            "n_forward": r.n_forward, "n_sensitivity": r.n_sensitivity,
            "wall_s_per_evaluation": wall / max(r.n_forward, 1), "converged": r.converged,
            "truth": truth, "start": start, "estimate": est, "se": r.se,
            "z": {n: (est[n] - truth[n]) / r.se[n] for n in FREE}, "chi2_per_dof": r.chi2_per_dof,
            "one_prediction_with_sensitivities_s": one, "assembly_s_summed": assembly,
            "linear_solve_s_summed": solve, "newton_per_step": newton}


def summary_lines(res: dict[str, Any]) -> list[str]:
    """The figures of :func:`run` as lines of text."""
    r = res
    out = [f"{r['n_params']} parameters from {r['n_protocols']} protocols x {r['periods']} periods, "
           f"{r['n_dof']} unknowns, {r['workers']} workers: fit {r['wall_s_fit'] / 60:.1f} min "
           f"({r['n_forward']} evaluations with sensitivities, {r['wall_s_per_evaluation']:.0f} s each); "
           f"virtual record simulated in {r['wall_s_session'] / 60:.1f} min",
           f"  one prediction with sensitivities {r['one_prediction_with_sensitivities_s']:.0f} s: "
           f"assembly {r['assembly_s_summed']:.0f} s, linear solves {r['linear_solve_s_summed']:.0f} s "
           f"(summed over protocols), {r['newton_per_step']:.2f} Newton iterations per step"]
    for n in FREE:
        out.append(f"  {n:12s} truth {res['truth'][n]:.5g}  estimate {res['estimate'][n]:.5g} "
                   f"± {1.96 * res['se'][n]:.2g}  (z {res['z'][n]:+.2f})")
    return out
