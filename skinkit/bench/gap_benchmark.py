"""Running the withheld-effect benchmark: planning the cases, running them in this process,
worker processes or a Dask cluster, journaling each as it finishes, and the summary lines.

The rules and their justification are in :mod:`skinkit.bench.gap_cases`."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from skinkit.bench.gap_cases import (
    ALPHA,
    DEFINITIONS,
    FULL_NULLS,
    FULL_PAIRS,
    MAGNITUDES,
    NULL_SEED0,
    OCCUPIED_SHARE,
    QUICK_EFFECTS,
    QUICK_NULLS,
    BenchmarkError,
    calibrate,
    effect_at,
    lumped_spec,
    model_spec,
    quick_spec,
    release,
    run_case,
)
from skinkit.bench.gap_score import assess, clopper_pearson, score
from skinkit.bench.task_pool import TaskPool


# -- planning and running -----------------------------------------------------------------------
def plan(calibrations: Sequence[Mapping[str, Any]], *, magnitudes: Sequence[str], seeds: int, nulls: int,
         pairs: int) -> list[dict[str, Any]]:
    """The cases: every calibrated effect × magnitude × seed, ``pairs`` pairs of effects at
    moderate magnitude (neighbours in the list of effects, one seed), ``nulls`` null sessions."""
    cases: list[dict[str, Any]] = []
    ok = [c for c in calibrations if "skipped" not in c]
    for c in ok:
        for mag in magnitudes:
            m = c["magnitudes"].get(mag)
            if m is None:
                continue
            for seed in range(seeds):
                cases.append({"id": f"{c['effect']}/{mag}/{seed}", "kind": "effect", "magnitude": mag,
                              "effects": [m["effect"]], "seed": seed})
    usable = [c for c in ok if "moderate" in c["magnitudes"]]
    for i in range(min(pairs, len(usable) // 2)):
        a, b = usable[2 * i], usable[2 * i + 1]
        cases.append({"id": f"{a['effect']}+{b['effect']}/moderate/0", "kind": "pair",
                      "magnitude": "moderate", "seed": 0,
                      "effects": [x["magnitudes"]["moderate"]["effect"] for x in (a, b)]})
    for i in range(nulls):
        cases.append({"id": f"null/{NULL_SEED0 + i}", "kind": "null", "magnitude": None, "effects": [],
                      "seed": NULL_SEED0 + i})
    return cases


def execution_order(cases: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """``cases`` in the order they run: seed by seed (a run stopped part-way has whole seeds),
    within a seed pairs, then moderate, then near (the longest first: the pool's tail is short),
    the null sessions after the first seed."""
    def key(c: Mapping[str, Any]) -> tuple[int, int]:
        if c["kind"] == "null":
            return (0, 3)
        rank = {"pair": 0, "moderate": 1}.get(c["kind"] if c["kind"] == "pair" else c["magnitude"], 2)
        return (int(c["seed"]) if int(c["seed"]) == 0 else int(c["seed"]) + 1, rank)

    return sorted(cases, key=key)


def _open_journal(journal: str | os.PathLike[str] | None, settings: Mapping[str, Any],
                  say: Callable[[str], None], read_only: bool = False) -> Any:
    if journal is None:
        return None
    from skinkit.bench.gap_journal import Journal

    jr = Journal(journal, settings, read_only=read_only)
    if jr.cases or jr.calibrations:
        say(f"journal {journal}: {len(jr.calibrations)} calibrations and {len(jr.cases)} cases recorded")
    return jr


def _calibrations(pool: TaskPool, tasks: Sequence[Mapping[str, Any]], jr: Any,
                  say: Callable[[str], None], recorded_only: bool = False) -> list[dict[str, Any]]:
    """The calibrations of ``tasks`` (one per effect, in order): from the journal ``jr`` when it
    holds them, else run on ``pool`` (and recorded) — or left out (``recorded_only``)."""
    def cal_line(c: Mapping[str, Any]) -> None:
        if "skipped" in c:
            say(f"calibrate {c['effect']}: skipped ({c['skipped']})")
        else:
            scales = ", ".join(f"{m} x{v['scale']:.3g} ({v['multiple']:.1f} thresholds)"
                               for m, v in c["magnitudes"].items())
            say(f"calibrate {c['effect']}: {scales}, {c.get('wall_s', 0):.1f} s")
        if jr is not None:
            jr.add_calibration(c)

    known = {} if jr is None else jr.calibrations
    todo = [] if recorded_only else [t for t in tasks if t["effect"] not in known]
    new = {c["effect"]: c for c in pool.map(calibrate, todo, cal_line)}
    return [new[t["effect"]] if t["effect"] in new else known[t["effect"]] for t in tasks
            if t["effect"] in new or t["effect"] in known]


def _run_cases(pool: TaskPool, payloads: Sequence[Mapping[str, Any]], jr: Any,
               say: Callable[[str], None], recorded_only: bool = False) -> tuple[list[dict[str, Any]], int]:
    """The records of ``payloads`` in their order, and how many came from the journal ``jr``;
    the others run on ``pool`` in :func:`execution_order`, each recorded as it finishes (or,
    ``recorded_only``, are left out)."""
    known = {} if jr is None else jr.cases
    before = {p["id"]: known[p["id"]] for p in payloads if p["id"] in known}
    if recorded_only:
        return [before[p["id"]] for p in payloads if p["id"] in before], len(before)
    todo = execution_order([p for p in payloads if p["id"] not in before])
    n_done = [len(before)]

    def case_line(r: Mapping[str, Any]) -> None:
        n_done[0] += 1
        named = "error" not in r and ", ".join(r["report"]["named"])
        what = f"error: {r['error']}" if "error" in r else f"named {named or 'none'}"
        say(f"case {n_done[0]}/{len(payloads)} {r['id']}: {what}, {r['wall_s']:.1f} s")
        if jr is not None:
            jr.add_case(r)

    if before:
        say(f"{len(before)} of {len(payloads)} cases from the journal, {len(todo)} to run")
    fresh = {r["id"]: r for r in pool.map(run_case, todo, case_line)}
    return [before[p["id"]] if p["id"] in before else fresh[p["id"]] for p in payloads], len(before)


def run(quick: bool, scheduler: str | None = None, workers: int | None = None, seeds: int | None = None,
        progress: Callable[[str], None] | None = None, *, model: str | Mapping[str, Any] | None = None,
        effects: Sequence[str] | None = None, nulls: int | None = None, pairs: int | None = None,
        magnitudes: Sequence[str] | None = None, parallel: int | None = None,
        max_effects: int | None = None, candidates: int | None = None,
        journal: str | os.PathLike[str] | None = None, recorded_only: bool = False,
        mesh: str = "own") -> dict[str, Any]:
    """Run the benchmark and score it (JSON-ready).

    ``quick``: the quick run (:data:`QUICK_EFFECTS` that apply and are visible, moderate
    magnitude only, one seed, :data:`QUICK_NULLS` null sessions, no pairs); otherwise every
    applicable effect at both magnitudes, ``seeds`` seeds (default 3), :data:`FULL_PAIRS` pairs
    and :data:`FULL_NULLS` null sessions. ``model``: a preset (``"quick"``: the coarse in vivo
    model, the default; ``"lumped"``), a model file or a description. ``effects``: restrict the
    truths to these. ``scheduler``: a Dask scheduler address (one task per case);
    ``parallel``: worker processes otherwise (default 2; 1 runs in this process); ``workers``:
    worker processes of each FE prediction (default 1 when cases run in parallel, else
    one per protocol up to the CPU count). ``progress(line)``: one line per calibrated effect
    and per case. ``max_effects`` (default 1 quick, 2 full) and ``candidates`` (refits per round,
    default 2 quick, 3 full) go to each :func:`~skinkit.gap.diagnose.diagnose`. ``journal``: a
    file (:mod:`skinkit.bench.gap_journal`) that records each calibration and case as it finishes; the
    ones it already holds are not run again (resuming a stopped run, or adding seeds or null
    sessions to a finished one); ``recorded_only``: run nothing, score the planned cases the
    journal holds (``planned_cases`` says how many were planned). ``mesh``: a finite-element truth
    on a mesh of its own (``"own"``, the default: the model's discretisation error is in the data and
    the diagnosis carries it) or on the model's (``"shared"``); each case records
    ``truth_unknowns`` and ``model_unknowns``. Cases run seed by seed (a
    stopped run has whole seeds), longest first within a seed, null sessions after the first
    seed. Keys:
    ``top1_accuracy``, ``null_false_alarm_rate``, ``localisation_accuracy``,
    ``magnitude_error_median``, ``shrinkage_error_median``, ``confusion``, ``cases`` (the
    records), ``wall_s``, and the details of :func:`score`, ``calibration``, ``skipped``.
    """
    from skinkit.forward import model_kind
    from skinkit.forward.visibility import applicable_effects

    t0 = time.perf_counter()
    say = progress or (lambda line: None)
    spec, free = model_spec(model)
    kind = model_kind(spec)
    names = applicable_effects(kind)
    if effects is not None:
        unknown = sorted(set(effects) - set(names))
        if unknown:
            raise BenchmarkError(f"--effects: {', '.join(unknown)} not installed or not applicable to a "
                                 f"{kind} model (applicable: {', '.join(names)})")
        names = [n for n in names if n in set(effects)]
    elif quick:
        names = [n for n in QUICK_EFFECTS if n in names] or names[:4]
    mags = list(magnitudes) if magnitudes is not None else (["moderate"] if quick else list(MAGNITUDES))
    bad = sorted(set(mags) - set(MAGNITUDES))
    if bad:
        raise BenchmarkError(f"magnitudes: unknown {bad}; choose from {list(MAGNITUDES)}")
    seeds = (1 if quick else 3) if seeds is None else int(seeds)
    nulls = (QUICK_NULLS if quick else FULL_NULLS) if nulls is None else int(nulls)
    pairs = (0 if quick else FULL_PAIRS) if pairs is None else int(pairs)
    parallel = 2 if parallel is None else int(parallel)
    if workers is None and (parallel > 1 or scheduler):
        workers = 1          # the cases are the parallel unit: one process per FE prediction
    opts = {"max_effects": (1 if quick else 2) if max_effects is None else int(max_effects),
            "candidates": (2 if quick else 3) if candidates is None else int(candidates)}
    if recorded_only and journal is None:
        raise BenchmarkError("--recorded-only scores a journal's cases: give --journal FILE")
    if recorded_only and not Path(journal).is_file():
        raise BenchmarkError(f"--recorded-only: journal {journal} does not exist")
    from skinkit.lab.truth_mesh import check_mode

    check_mode(mesh, 2)
    jr = _open_journal(journal, {"model": spec, "free": free, "mesh": mesh,
                                 "magnitudes": {m: MAGNITUDES[m] for m in mags},
                                 "diagnose": opts, "alpha": ALPHA, "definitions": DEFINITIONS}, say,
                      read_only=recorded_only)
    pool = TaskPool(1, None) if recorded_only else TaskPool(parallel, scheduler)
    try:
        tasks = [{"spec": spec, "free": free, "effect": n, "workers": workers, "mesh": mesh,
                  "magnitudes": {m: MAGNITUDES[m] for m in mags}} for n in names]
        cals = _calibrations(pool, tasks, jr, say, recorded_only)
        cases = plan(cals, magnitudes=mags, seeds=seeds, nulls=nulls, pairs=pairs)
        if not any(c["kind"] != "null" for c in cases) and names:
            say("no effect is visible on these protocols: only null sessions run")
        payloads = [dict(c, spec=spec, free=free, workers=workers, diagnose=opts, mesh=mesh) for c in cases]
        records, n_resumed = _run_cases(pool, payloads, jr, say, recorded_only)
    finally:
        pool.close()
        release()
    out = score(records)
    out.update({"model": spec.get("model", {}).get("name"), "kind": kind, "quick": bool(quick), "mesh": mesh,
                "free": free, "effects": names, "magnitudes": {m: MAGNITUDES[m] for m in mags},
                "occupied_share": OCCUPIED_SHARE, "alpha": ALPHA, "diagnose_options": opts,
                "calibration": {c["effect"]: c for c in cals},
                "skipped": {c["effect"]: c["skipped"] for c in cals if "skipped" in c},
                "cases": records, "wall_s": time.perf_counter() - t0,
                "resumed_cases": n_resumed, "planned_cases": len(payloads)})
    return out


# -- command ------------------------------------------------------------------------------------
def summary_lines(res: Mapping[str, Any]) -> list[str]:
    """The run's figures as the lines ``skinkit gap benchmark`` prints."""
    def pct(r: Mapping[str, Any]) -> str:
        if not r["n"]:
            return "-"
        lo, hi = r["interval_95"]
        return f"{100 * r['rate']:.0f} % ({r['k']}/{r['n']}; 95 % CI {100 * lo:.0f}-{100 * hi:.0f} %)"

    def num(x: Any) -> str:
        return "-" if x is None else f"{100 * x:.1f} %"

    sizes = {(c.get("truth_unknowns"), c.get("model_unknowns")) for c in res["cases"]
             if c.get("truth_unknowns")}
    meshes = ([f"truths on {res.get('mesh', 'own')} meshes: "
               + ", ".join(f"{t:,} unknowns (model {m:,})" for t, m in sorted(sizes))] if sizes else [])
    lines = [f"model {res['model']} ({res['kind']}), {len(res['cases'])} of {res['planned_cases']} planned "
             f"cases, {res['wall_s'] / 60:.1f} min", *meshes,
             f"top-1 attribution (separable, moderate): {pct(res['top1'])}",
             f"truth in the reported set (not separable, moderate): "
             f"{pct(res['by_magnitude']['moderate']['in_reported_set'])}",
             f"false alarms on null sessions: {pct(res['null_false_alarm'])}",
             f"'significant gap' on null sessions (level {100 * res['alpha']:.0f} %): "
             f"{pct(res['null_gap_significant'])}",
             f"localisation: {pct(res['localisation'])}",
             f"magnitude error (median |relative|, moderate): {num(res['magnitude_error_median'])}",
             f"shrinkage error vs oracle (median |relative|, moderate): {num(res['shrinkage_error_median'])}"
             f" (unclipped: median {num(res['shrinkage_errors'].get('unclipped_median'))}, "
             f"max {num(res['shrinkage_errors'].get('unclipped_max'))})",
             f"time per case: median {res['case_wall_s']['median'] or 0:.1f} s, "
             f"max {res['case_wall_s']['max'] or 0:.1f} s"]
    if res["by_magnitude"].get("near", {}).get("cases"):
        lines.append("near the detection limit: named something in "
                     f"{pct(res['by_magnitude']['near']['named_any'])}")
    for e, why in res["skipped"].items():
        lines.append(f"skipped {e}: {why}")
    for c in res.get("not_visible", []):
        g = c["oracle_gain"]
        lines.append(f"not counted {c['id']}: the session does not show it (the true structure's refit gains "
                     f"χ² {g['chi2']:.3g} on {g['dof']} parameters, within noise); named "
                     f"{', '.join(c['named']) or 'none'}")
    lines.append("confusion (true -> named):")
    for t, row in sorted(res["confusion"].items()):
        ranked = sorted(row.items(), key=lambda kv: -kv[1])
        lines.append(f"  {t}: " + ", ".join(f"{k} {v}" for k, v in ranked))
    return lines


# the benchmark's public API in one place: cases and rules (gap_cases), scores (gap_score), running
__all__ = ["ALPHA", "MAGNITUDES", "BenchmarkError", "assess", "calibrate", "clopper_pearson", "effect_at",
           "execution_order", "lumped_spec", "model_spec", "plan", "quick_spec", "release", "run", "run_case",
           "score", "summary_lines"]
