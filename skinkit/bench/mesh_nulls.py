"""Nulls with the mesh gap only: truths on meshes of their own, no effect, diagnosed by the model on
its coarse mesh.

Each case is a small finite-element model (:data:`CASES`) whose truth the virtual lab solves on a
mesh of its own (:mod:`skinkit.lab.truth_mesh`) and records with fresh noise per seed; the gap
diagnosis of the model without any effect must name nothing. It runs twice per session: with the
model's discretisation error carried as noise (the default, :mod:`skinkit.inverse.approximation`)
and without (``--no-model-error --no-error-estimate``), so that the figure says what carrying the
error buys. Counts come with exact (Clopper-Pearson) 95 % intervals.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Sequence
from typing import Any

from skinkit.bench.gap_score import clopper_pearson

#: candidate effects every null is diagnosed against (ones a mesh too stiff would imitate)
CANDIDATES = ("support-compliance", "inclusion", "thickness", "force-offset")


def _disc() -> tuple[dict[str, Any], list[str]]:
    """A layered disc (neo-Hookean skin over subdermal tissue), a bonded 4 mm indenter driven by
    displacement, one normal-indentation period: the moduli free."""
    return {
        "model": {"name": "disc-two-layers"},
        "geometry": {"kind": "disc", "diameter": "30 mm", "indenter_diameter": "4 mm",
                     "n_inner": 1, "n_ring": 1, "grading": 1.6},
        "layers": [
            {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "neo-hookean-enu",
             "parameters": {"E": "60 kPa", "nu": 0.45}},
            {"name": "subdermal", "thickness": "3.5 mm", "elements": 1, "law": "neo-hookean-enu",
             "parameters": {"E": "10 kPa", "nu": 0.45}},
        ],
        "boundary": {"fixed": ["outer", "bottom"]},
        "indenter": {"mode": "displacement"},
        "drive": {"max_step": "1 s"},
        "surface": {"fit": False},
        "solver": {"rtol": 1e-8, "intorder": 4},
        "session": {"protocols": ["normal_indentation"],
                    "parameters": {"normal_indentation": {"periods": 1}}},
    }, ["skin.E", "subdermal.E"]


def _gel() -> tuple[dict[str, Any], list[str]]:
    """One homogeneous gel layer under the same indenter: its modulus free."""
    spec, _ = _disc()
    spec["model"] = {"name": "disc-gel"}
    spec["layers"] = [{"name": "gel", "thickness": "5 mm", "elements": 2, "law": "neo-hookean-enu",
                       "parameters": {"E": "10 kPa", "nu": 0.45}}]
    return spec, ["gel.E"]


#: case name -> (description, free parameters)
CASES: dict[str, Callable[[], tuple[dict[str, Any], list[str]]]] = {
    "disc-two-layers": _disc, "disc-gel": _gel}


def run(cases: Sequence[str], seeds: int, first_seed: int = 0, workers: int = 1,
        say: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Diagnose ``seeds`` sessions of each case with and without the carried model error; per
    mode the count of sessions with a cause named, with its 95 % interval, and every case's
    verdict."""
    from skinkit.gap.diagnose import diagnose
    from skinkit.inverse.coverage import LabSessions

    say = say or (lambda _m: None)
    t0 = time.perf_counter()
    rows: list[dict[str, Any]] = []
    meshes: dict[str, Any] = {}
    for name in cases:
        spec, free = CASES[name]()
        lab = LabSessions(spec, workers=workers)
        meshes[name] = lab.truth.truth["mesh"]
        for seed in range(first_seed, first_seed + seeds):
            obs = lab(seed)
            for carried in (True, False):
                t = time.perf_counter()
                rep = diagnose(copy.deepcopy(lab.model_spec), obs, effects=list(CANDIDATES), free=free,
                               workers=workers, max_effects=1, candidates=1, model_error=carried,
                               error_estimate=False).to_dict()
                err = rep.get("model_error") or {}
                rows.append({"case": name, "seed": seed, "model_error": carried, "named": rep["named"],
                             "minor": rep.get("minor", []), "chi2_per_dof": rep["fit"]["chi2_per_dof"],
                             "accounts_for": err.get("accounts_for"),
                             "remaining_significant": rep["remaining"]["significant"],
                             "wall_s": time.perf_counter() - t})
                say(f"{name} seed {seed} {'carried' if carried else 'ignored'}: named "
                    f"{', '.join(rep['named']) or 'nothing'} ({rows[-1]['wall_s']:.0f} s)")
    out: dict[str, Any] = {"cases": list(cases), "seeds": seeds, "candidates": list(CANDIDATES),
                           "meshes": meshes, "rows": rows, "wall_s": time.perf_counter() - t0}
    for carried, key in ((True, "carried"), (False, "ignored")):
        sel = [r for r in rows if r["model_error"] is carried]
        k = sum(1 for r in sel if r["named"])
        out[key] = {"named": k, "n": len(sel), "rate": k / len(sel) if sel else None,
                    "interval_95": clopper_pearson(k, len(sel))}
    return out


def summary_lines(res: dict[str, Any]) -> list[str]:
    """The figures as text lines."""
    lines = [f"nulls with the mesh gap only: {', '.join(res['cases'])}, {res['seeds']} seeds each, "
             f"candidates {', '.join(res['candidates'])}; {res['wall_s'] / 60:.1f} min"]
    for name, m in res["meshes"].items():
        lines.append(f"  {name}: truth {m['truth_unknowns']:,} unknowns on its own mesh, model "
                     f"{m['model_unknowns']:,}")
    for key, what in (("carried", "model error carried as noise"), ("ignored", "model error ignored")):
        s = res[key]
        lo, hi = s["interval_95"]
        lines.append(f"{what}: a cause named in {s['named']}/{s['n']} "
                     f"({100 * s['rate']:.0f} %; 95 % CI {100 * lo:.0f}-{100 * hi:.0f} %)")
    return lines


__all__ = ["CANDIDATES", "CASES", "run", "summary_lines"]
