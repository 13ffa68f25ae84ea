"""``skinkit bench diagnose``: where a finite-element gap diagnosis spends its time, by stage.

Each case is a virtual-lab session whose truth holds one effect the model lacks, solved on a mesh
of its own (the model's discretisation error then carried as noise, as the product runs by
default) or on the model's (``mesh="shared"``):

- ``forearm``: the demo's virtual forearm (:mod:`skinkit.lab.forearm`, its quick protocols, the top
  flat so that truth and model share it), pre-stress withheld, c, k1, κ and g1 free;
- ``quick-case``: the quick gap benchmark's model (:func:`skinkit.bench.gap_cases.quick_spec`)
  with a compliant support withheld.

The diagnosis runs as ``skinkit gap diagnose`` runs it (one effect named at most, two candidates
refitted) inside a :func:`skinkit.forward.stages.recording`: per stage (calibration, model error,
score sensitivities, discretisation check, each refit, separation, how far, final model, reporting) its own
seconds and forward equivalents (whole-session predictions), and how every parameter's
derivative was computed. One plain prediction of the calibrated model is timed apart, so that
seconds and forward equivalents can be compared.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Sequence
from typing import Any


def _forearm() -> tuple[dict[str, Any], list[str]]:
    from skinkit.lab import forearm

    spec = forearm.truth_spec(quick=True)
    spec["surface"] = {"fit": False}
    return spec, list(forearm.FREE)


def _quick_case() -> tuple[dict[str, Any], list[str]]:
    from skinkit.bench.gap_cases import plugin_values, quick_spec

    spec, free = quick_spec()
    typical, _, _ = plugin_values("support-compliance")
    spec = copy.deepcopy(spec)
    spec["effects"] = [{"name": "support-compliance", **typical}]
    return spec, list(free)


#: case name -> the truth's description (with its withheld effect) and the model's free parameters
CASES: dict[str, Callable[[], tuple[dict[str, Any], list[str]]]] = {
    "forearm": _forearm, "quick-case": _quick_case}


def profile_case(name: str, mesh: str = "own", workers: int = 2, seed: int = 0,
                 say: Callable[[str], None] | None = None) -> dict[str, Any]:
    """One case's diagnosis by stage (see the module docstring)."""
    from skinkit.forward import load
    from skinkit.forward.stages import recording
    from skinkit.gap.diagnose import diagnose
    from skinkit.inverse.coverage import LabSessions

    say = say or (lambda _m: None)
    spec, free = CASES[name]()
    withheld = [str(e["name"]) for e in spec.get("effects", [])]
    t0 = time.perf_counter()
    lab = LabSessions(spec, workers=workers, mesh=mesh)
    truth_s = time.perf_counter() - t0
    obs = lab(seed)
    model = copy.deepcopy(lab.model_spec)
    model["effects"] = []       # the withheld effect
    model["model"] = {"name": f"{name} (without {', '.join(withheld)})"}
    say(f"{name}: truth solved in {truth_s:.0f} s ({mesh} mesh); diagnosing")
    t1 = time.perf_counter()
    with recording() as clock:
        rep = diagnose(model, obs, free=free, workers=workers, max_effects=1, candidates=2,
                       model_error=mesh == "own", progress=lambda m: say(f"  {m}"))
    wall = time.perf_counter() - t1
    d = rep.to_dict()
    m = load(model, workers=workers)
    try:
        ps = m.parameters().with_values({k: float(v) for k, v in d["fit"]["parameters"].items()
                                         if k in m.parameters().names})
        m.predict(ps, obs)            # the worker pool started outside the timing
        t2 = time.perf_counter()
        m.predict(ps, obs)
        forward_s = time.perf_counter() - t2
    finally:
        m.close()
    prof = clock.to_dict()
    numerical = sorted(k for k, v in prof["methods"].items() if not v.startswith("analytic"))
    return {"case": name, "mesh": mesh, "withheld": withheld, "named": d["named"],
            "truth_wall_s": truth_s, "wall_s": wall, "forward_s": forward_s,
            "truth_unknowns": lab.truth.truth.get("mesh", {}).get("truth_unknowns"),
            "model_unknowns": lab.truth.truth.get("mesh", {}).get("model_unknowns"),
            "stages": prof["stages"], "forward_equivalents": prof["forward_equivalents"],
            "methods": prof["methods"], "numerical": numerical}


def run(cases: Sequence[str], mesh: str = "own", workers: int = 2,
        say: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Every case of ``cases`` profiled; JSON-ready."""
    return {"cases": [profile_case(c, mesh, workers, say=say) for c in cases], "workers": workers}


def summary_lines(res: dict[str, Any]) -> list[str]:
    """The figures as text lines: a table of stages per case."""
    out: list[str] = []
    for c in res["cases"]:
        out.append(f"{c['case']} ({c['mesh']} mesh; truth {c['truth_unknowns']} unknowns, model "
                   f"{c['model_unknowns']}; withheld {', '.join(c['withheld'])}; named "
                   f"{', '.join(c['named']) or 'nothing'}): diagnosis {c['wall_s']:.0f} s, "
                   f"{c['forward_equivalents']} forward equivalents, one forward {c['forward_s']:.1f} s")
        out.append(f"  {'stage':<34} {'seconds':>8} {'share':>6} {'forward eq.':>11} {'columns':>8}")
        total = sum(s["seconds"] for s in c["stages"]) or 1.0
        for s in c["stages"]:
            out.append(f"  {s['name']:<34} {s['seconds']:8.1f} {100 * s['seconds'] / total:5.0f}% "
                       f"{s['forward_equivalents']:11d} {s['sensitivity_columns']:8d}")
        num = c["numerical"]
        out.append("  derivatives: " + (f"by central differences: {', '.join(num)}" if num
                                        else f"all {len(c['methods'])} analytic"))
    return out


__all__ = ["CASES", "profile_case", "run", "summary_lines"]
