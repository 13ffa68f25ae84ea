"""Scar sessions: does the diagnosis find a stiff elliptical scar between two pads, where it is and
how stiff — and keep quiet on healthy skin?

Each case is a virtual two-pad extension session (``skinkit lab scar-session``,
:mod:`skinkit.lab.scar`): a truth on a mesh of its own, with a stiff elliptical scar at a random
place between the pads (stiffness ratio 2–10, semi-axes 4–12 mm across) or none (healthy), forces
and tracks at the real record's noise levels. The session is written to an experiment file and
diagnosed as a user would (:func:`skinkit.gap.diagnose.diagnose` with its defaults: every
installed effect that applies, region effects scanned over the tracked points).

Per scar case: ``inclusion`` named (a cause or a minor contribution), the found centre inside the
true outline (within one semi-axis along each of the scar's axes), and the true stiffness ratio
inside the fitted ratio's 95 % interval. Per healthy case: ``inclusion`` named is a false alarm.
Rates come with exact (Clopper–Pearson) 95 % intervals. The acceptance the figures answer:
named ≥ 90 %, centre ≥ 90 %, ratio coverage 90–99 % over ≥ 10 scar seeds; no ``inclusion`` on
≥ 95 % of ≥ 10 healthy seeds.

A case takes of order twenty minutes on one core: ``--parallel`` runs cases at once,
``--scheduler`` on a Dask cluster, and ``--journal`` records each finished case so that a run
stopped part-way goes on where it stopped.
"""

from __future__ import annotations

import math
import statistics
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from skinkit.bench.gap_score import clopper_pearson

#: the effect whose naming, position and stiffness are scored
EFFECT = "inclusion"
#: the z value of a two-sided 95 % interval
Z95 = 1.959963984540054


def inside_outline(centre: Sequence[float], scar: Mapping[str, Any]) -> bool:
    """Whether ``centre`` (x, y) [m] lies inside the truth's scar outline (the truth file's
    ``scar`` entry: centre ``x_m``, ``y_m``, semi-axes ``a_m``, ``b_m`` [m], ``angle_rad`` of
    ``a`` from the x axis): within one semi-axis of the true centre along each of its axes."""
    dx, dy = centre[0] - scar["x_m"], centre[1] - scar["y_m"]
    c, s = math.cos(scar["angle_rad"]), math.sin(scar["angle_rad"])
    u, v = c * dx + s * dy, -s * dx + c * dy
    return (u / scar["a_m"]) ** 2 + (v / scar["b_m"]) ** 2 <= 1.0


def _found(report: Mapping[str, Any]) -> dict[str, Any] | None:
    """The fitted ``inclusion`` of a diagnosis report (JSON): its values by the parameter's last
    name and their standard errors under ``se``, from the final model (its refit with its own
    discretisation error) or, when that is missing, from the candidate's refit; None when the
    effect was not added."""
    prefix = f"{EFFECT}."
    values = report.get("final_parameters") or {}
    if any(k.startswith(prefix) for k in values):
        se = report.get("final_se") or {}
        out = {k[len(prefix):]: v for k, v in values.items() if k.startswith(prefix)}
        out["se"] = {k[len(prefix):]: v for k, v in se.items() if k.startswith(prefix)}
        return out
    for cand in report.get("candidates", []) or []:
        if cand.get("effect") == EFFECT and cand.get("role") in ("cause", "minor"):
            pars = cand.get("parameters") or {}
            out = {k.split(".")[-1]: v.get("value") for k, v in pars.items() if isinstance(v, Mapping)}
            out["se"] = {k.split(".")[-1]: v.get("se") for k, v in pars.items() if isinstance(v, Mapping)}
            return out
    return None


def score_case(report: Mapping[str, Any], scar: Mapping[str, Any] | None) -> dict[str, Any]:
    """The scored figures of one diagnosis ``report`` (its JSON) against the truth's ``scar``
    (None: a healthy session)."""
    named = EFFECT in (report.get("named", []) or []) or EFFECT in (report.get("minor", []) or [])
    out: dict[str, Any] = {"named": list(report.get("named", []) or []),
                           "minor": list(report.get("minor", []) or []), "inclusion_named": named}
    if scar is None:
        return out
    found = _found(report)
    out["found"] = found
    if found is None or "x" not in found or "y" not in found:
        out.update(centre_inside=False, ratio_covered=False)
        return out
    out["centre_error_mm"] = 1e3 * math.hypot(found["x"] - scar["x_m"], found["y"] - scar["y_m"])
    out["centre_inside"] = inside_outline((found["x"], found["y"]), scar)
    ratio, se = found.get("ratio"), found.get("se", {}).get("ratio")
    out["ratio_covered"] = (ratio is not None and se is not None and math.isfinite(se)
                            and abs(ratio - scar["ratio"]) <= Z95 * se)
    return out


def scar_case(task: Mapping[str, Any]) -> dict[str, Any]:
    """One case: write the session of ``task["seed"]`` (a scar, or none when ``task["healthy"]``),
    diagnose it with the defaults, score it. Returns the case record (``id``, the truth's scar,
    the scored figures, the wall time)."""
    from skinkit.gap.diagnose import diagnose
    from skinkit.lab.scar import make_scar_session, model_spec

    t0 = time.perf_counter()
    seed, healthy = int(task["seed"]), bool(task["healthy"])
    with tempfile.TemporaryDirectory(prefix="skinkit-scar-") as tmp:
        session, truth_file = Path(tmp) / "session.h5", Path(tmp) / "truth.json"
        truth = make_scar_session(session, truth_file, seed, healthy=healthy, workers=1)
        t_sim = time.perf_counter() - t0
        report = diagnose(model_spec(), str(session), workers=1).to_dict()
    scar = truth.get("scar")
    final_error = report.get("final_model_error") or {}
    return {"id": case_id(task), "seed": seed, "healthy": healthy, "scar": scar,
            **score_case(report, scar), "chi2_per_dof": report.get("fit", {}).get("chi2_per_dof"),
            # the mesh the final model was fitted on, and why (the model mesh's resolution)
            "final_member": final_error.get("member"), "resolution": final_error.get("resolution"),
            "simulate_s": t_sim, "wall_s": time.perf_counter() - t0}


def case_id(task: Mapping[str, Any]) -> str:
    """The journal key of a task: ``scar-<seed>`` or ``healthy-<seed>``."""
    return f"{'healthy' if task['healthy'] else 'scar'}-{int(task['seed'])}"


def _rate(k: int, n: int) -> dict[str, Any]:
    return {"count": k, "n": n, "rate": k / n if n else None, "interval_95": clopper_pearson(k, n)}


def summarise(records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The rates over case ``records``: inclusion named, centre inside and ratio covered over the
    scar cases, inclusion named (false alarms) over the healthy ones."""
    scars = [r for r in records if not r["healthy"]]
    healthy = [r for r in records if r["healthy"]]
    return {"scar_cases": len(scars), "healthy_cases": len(healthy),
            "named": _rate(sum(r["inclusion_named"] for r in scars), len(scars)),
            "centre_inside": _rate(sum(bool(r.get("centre_inside")) for r in scars), len(scars)),
            "ratio_covered": _rate(sum(bool(r.get("ratio_covered")) for r in scars), len(scars)),
            "false_alarms": _rate(sum(r["inclusion_named"] for r in healthy), len(healthy))}


def run(scars: int, healthy: int, first_seed: int = 0, parallel: int = 1, scheduler: str | None = None,
        journal: str | Path | None = None, say: Callable[[str], None] | None = None,
        case: Callable[[Mapping[str, Any]], dict[str, Any]] = scar_case) -> dict[str, Any]:
    """Run ``scars`` scar and ``healthy`` healthy cases (seeds from ``first_seed``) on ``parallel``
    processes or a Dask ``scheduler``; cases recorded in ``journal`` are read back, not run.
    Returns the records and :func:`summarise`'s rates."""
    from skinkit.bench.gap_journal import Journal
    from skinkit.bench.task_pool import TaskPool

    say = say or (lambda _m: None)
    t0 = time.perf_counter()
    tasks = ([{"seed": first_seed + i, "healthy": False} for i in range(scars)]
             + [{"seed": first_seed + i, "healthy": True} for i in range(healthy)])
    jr = Journal(journal, {"benchmark": "scar sessions", "effect": EFFECT}) if journal else None
    known = {} if jr is None else jr.cases
    todo = [t for t in tasks if case_id(t) not in known]
    if jr is not None and len(todo) < len(tasks):
        say(f"journal {journal}: {len(tasks) - len(todo)} of {len(tasks)} cases recorded")

    def done(rec: dict[str, Any]) -> None:
        if jr is not None:
            jr.add_case(rec)
        what = ("inclusion named" if rec["inclusion_named"] else "no inclusion") + (
            "" if rec["healthy"] else f", centre {'inside' if rec.get('centre_inside') else 'outside'}, "
                                      f"ratio {'covered' if rec.get('ratio_covered') else 'missed'}")
        say(f"{rec['id']}: {what} ({rec['wall_s']:.0f} s)")

    pool = TaskPool(parallel, scheduler)
    try:
        new = {r["id"]: r for r in pool.map(case, todo, done)}
    finally:
        pool.close()
    records = [new.get(case_id(t)) or known[case_id(t)] for t in tasks]
    return {"scar_seeds": scars, "healthy_seeds": healthy, "first_seed": first_seed,
            "effect": EFFECT, **summarise(records), "cases": records, "from_journal": len(tasks) - len(todo),
            "wall_s": time.perf_counter() - t0}


def summary_lines(res: Mapping[str, Any]) -> list[str]:
    """The figures as text lines."""
    def pct(r: Mapping[str, Any]) -> str:
        if not r["n"]:
            return "no cases"
        lo, hi = r["interval_95"]
        return f"{r['count']}/{r['n']} ({100 * r['rate']:.0f} %; 95 % CI {100 * lo:.0f}-{100 * hi:.0f} %)"

    cases = [float(c["wall_s"]) / 60 for c in res.get("cases", []) if c.get("wall_s") is not None]
    took = (f"; a case {statistics.median(cases):.1f} min (median), {max(cases):.1f} min at most, on one core"
            if cases else "")
    resumed = res.get("from_journal") or 0
    return [f"scar sessions: {res['scar_cases']} with a scar, {res['healthy_cases']} healthy "
            f"(seeds from {res['first_seed']}); this run {res['wall_s'] / 60:.1f} min"
            + (f" ({resumed} cases read from the journal)" if resumed else "") + took,
            f"  {EFFECT} named on scar sessions: {pct(res['named'])}   (target >= 90 %)",
            f"  found centre inside the true outline: {pct(res['centre_inside'])}   (target >= 90 %)",
            f"  true ratio inside the 95 % interval: {pct(res['ratio_covered'])}   (target 90-99 %)",
            f"  {EFFECT} named on healthy sessions: {pct(res['false_alarms'])}   (target <= 5 %)"]


__all__ = ["EFFECT", "case_id", "inside_outline", "run", "scar_case", "score_case", "summarise",
           "summary_lines"]
