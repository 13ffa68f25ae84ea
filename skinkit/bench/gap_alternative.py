"""The alternative gap benchmark: the diagnosis checked on truths it did not make.

The withheld-effect benchmark (:mod:`skinkit.bench.gap_benchmark`) makes its truths with the
effect plugins the diagnosis tests, in their own forms, with white Gaussian noise: it shows
the diagnosis consistent with itself. Here the truths come from :mod:`skinkit.lab.alternative`
(NumPy forms written apart from the plugins, coloured and spiky noise, artefacts no effect
describes) on the lumped extension model, or from :mod:`skinkit.lab.alternative_fe` on the quick
finite-element model (preset ``"quick"``: forms put on its recorded force), and the model without
any effect is diagnosed (:func:`skinkit.gap.diagnose.diagnose`, the same as ``skinkit gap diagnose``).

**Reading a report.** The causes are the report's ``named`` list, in naming order (the
candidates whose ``role`` is ``"cause"`` when ``named`` is absent); an instance label
``<effect>-<k>`` (a further term of an effect) counts as ``<effect>``. What is left is the
report's ``remaining`` block; a report without one leaves it unknown, except when nothing is
named: the remainder is then the first gap, and its ``significant`` is the gap's.

**Scores** (:func:`score`), each with a Clopper–Pearson 95 % interval:

* ``top1_accuracy``: effect cases whose first cause is the truth's effect;
* ``spurious_rate``: effect cases with a cause named that the truth lacks;
* ``null_false_alarm_rate``: null sessions with any cause named;
* ``null_gap_significant_rate``: null sessions reported as a significant gap (``gap`` or
  ``remaining``);
* ``unexplained_recall``: out-of-library cases with no cause named and the remainder
  significant (the right answer: nothing explains it, and something is there).
"""

from __future__ import annotations

import functools
import math
import os
import re
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.bench.gap_benchmark import _open_journal
from skinkit.bench.gap_cases import ALPHA, BenchmarkError
from skinkit.bench.gap_score import clopper_pearson
from skinkit.bench.task_pool import TaskPool
from skinkit.errors import SkinkitError

#: the diagnosed model's free parameters: the element's a, b and the force zero
FREE = ("lumped.a", "lumped.b", "offset.x")
#: the models the alternative truths are written for, and the lab modules that write them
PRESETS = {"lumped": "skinkit.lab.alternative", "quick": "skinkit.lab.alternative_fe"}
#: the kind of model of each preset
KINDS = {"lumped": "lumped", "quick": "fe"}
FULL_SEEDS = 5
QUICK_SEEDS = 1
#: version of these definitions a journal's cases were made under
DEFINITIONS = 1
#: the diagnosis options: quick as the withheld-effect benchmark's quick run, full as its full run
QUICK_DIAGNOSE = {"max_effects": 1, "candidates": 2}
FULL_DIAGNOSE = {"max_effects": 2, "candidates": 3}


def model_spec(preset: str = "lumped") -> dict[str, Any]:
    """The model every truth of ``preset`` is diagnosed with: for ``"lumped"``,
    ``docs/models/extension_relaxation_lumped.toml`` (the exponential element and the force zero,
    no effect); for ``"quick"``, the quick finite-element preset with a rest before each protocol
    (:func:`skinkit.lab.alternative_fe.with_rest`)."""
    if _check(preset) == "quick":
        return _fe_spec()[0]
    from skinkit.examples import example_model
    from skinkit.fem.model import read_model

    spec = dict(read_model(example_model("extension_relaxation_lumped")))
    spec.pop("effects", None)
    spec.pop("session", None)
    return spec


def free(preset: str = "lumped") -> list[str]:
    """The diagnosed model's free parameters (:data:`FREE` for the lumped preset; c, k1, κ, g1
    for the finite-element one)."""
    if _check(preset) == "quick":
        return _fe_spec()[1]
    return list(FREE)


def _fe_spec() -> tuple[dict[str, Any], list[str]]:
    """The quick finite-element preset (:func:`skinkit.bench.gap_cases.quick_spec`) with a rest
    before every protocol (:func:`skinkit.lab.alternative_fe.with_rest`) and its free parameters."""
    from skinkit.bench.gap_cases import _plain, quick_spec
    from skinkit.lab.alternative_fe import with_rest

    spec, names = quick_spec()
    return with_rest(_plain(spec)), list(names)


def _check(preset: str) -> str:
    if preset not in PRESETS:
        raise BenchmarkError(f"--model: the alternative benchmark runs on {' or '.join(PRESETS)}, "
                             f"got {preset!r}")
    return preset


def _module(preset: str) -> Any:
    """The lab module of ``preset``'s truths (:data:`PRESETS`)."""
    import importlib

    return importlib.import_module(PRESETS[_check(preset)])


def forms(names: Sequence[str] | None = None, preset: str = "lumped") -> list[Any]:
    """The truth forms of ``preset`` (its lab module's ``FORMS``), or those ``names``
    (:class:`BenchmarkError` naming the known ones for an unknown name)."""
    all_forms = _module(preset).FORMS
    if names is None:
        return list(all_forms)
    known = {f.name: f for f in all_forms}
    bad = [n for n in names if n not in known]
    if bad:
        raise BenchmarkError(f"--forms: unknown {', '.join(bad)} (forms: {', '.join(known)})")
    return [known[n] for n in dict.fromkeys(names)]


def coverage(selected: Sequence[Any], applicable: Sequence[str], preset: str = "lumped"
             ) -> tuple[list[Any], dict[str, str]]:
    """The forms that can run (an effect form needs one of its accepted effects among the
    ``applicable`` ones: otherwise no answer could be right) and why the others, and the
    applicable effects no form stands for, are left out."""
    skipped_effects = _module(preset).SKIPPED_EFFECTS
    reason = getattr(_module(preset), "skipped_reason", None)
    ok, skipped = [], {}
    for f in selected:
        if f.family == "effect" and not set(f.accepted) & set(applicable):
            skipped[f"form {f.name}"] = (f"{' or '.join(f.accepted)} is not installed or does not apply to "
                                         f"{KINDS[preset]} models: no answer could be right")
        else:
            ok.append(f)
    covered = {e for f in ok for e in f.accepted}
    for e in applicable:
        if e not in covered:
            skipped[e] = (skipped_effects[e] if e in skipped_effects else reason(e) if reason is not None
                          else "no truth form stands for it (none written, or none chosen)")
    return ok, skipped


def plan(selected: Sequence[Any], seeds: int) -> list[dict[str, Any]]:
    """One case per form and seed (0 … ``seeds`` − 1), seed by seed so that a stopped run holds
    whole seeds: ``id`` ``family/form/seed``, ``family``, ``form``, ``effect`` (the form's
    effect), ``accepted`` (the effects a right answer may name), ``seed``."""
    return [{"id": f"{f.family}/{f.name}/{s}", "family": f.family, "form": f.name, "effect": f.effect,
             "accepted": list(f.accepted), "seed": s} for s in range(seeds) for f in selected]


# -- one case ---------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=32)
def visible_excess(name: str, preset: str = "lumped") -> dict[str, float]:
    """What form ``name`` shows beyond noise: the χ² (noise variances) the model leaves when fitted
    to the noiseless truth, its degrees of freedom and its multiple of the global χ² test's
    critical excess at α = 0.05 (the detection threshold)."""
    from scipy.stats import chi2

    from skinkit.forward import load
    from skinkit.inverse.fit import fit

    obs = session(name, None, preset)
    names = free(preset)
    # one process: this runs inside a benchmark's worker
    with load(model_spec(preset), workers=1) as model:
        r = fit(model, obs, names)
    if preset == "lumped":
        dof = sum(int(np.asarray(po.channels["tip_force"].values).shape[0]) for po in obs) - len(names)
    else:
        # every channel counts: the fit's χ² over its χ²/ν
        dof = int(round(sum(r.residual_by_channel.values()) / float(r.chi2_per_dof)))
    excess = float(r.chi2_per_dof) * dof
    threshold = float(chi2.ppf(1 - ALPHA, dof) - dof)
    return {"chi2": excess, "dof": dof, "threshold": threshold, "multiple": excess / threshold}


_INSTANCE = re.compile(r"^(?P<effect>.+)-(?P<k>\d+)$")


def session(name: str, seed: int | None, preset: str = "lumped") -> Any:
    """The virtual session of form ``name`` and ``seed`` (None: noiseless), read as any robot
    record is (:func:`skinkit.forward.observations.channels_from_record`): the noise level, its
    colour and the spikes are estimated from the record, not told to the diagnosis."""
    from skinkit.forward.observations import channels_from_record
    from skinkit.lab import alternative as alt
    from skinkit.schemas import Observations, ProtocolObservations

    if _check(preset) != "lumped":
        return _module(preset).session(name, seed, model_spec(preset))
    if seed is None:
        return alt.noiseless(name)
    chans = channels_from_record(alt.record(name, seed), f"alternative truth {name}")
    return Observations({alt.PROTOCOL: ProtocolObservations(alt.protocol(), chans)}, None,
                        f"alternative truth {name}, seed {seed}")


def effect_of(label: str) -> str:
    """The effect an instance label names: ``viscoelastic-2`` -> ``viscoelastic``."""
    m = _INSTANCE.match(label)
    return m.group("effect") if m else label


def reading(rep: Mapping[str, Any]) -> dict[str, Any]:
    """What a diagnosis report (``GapReport.to_dict()``) says, in the scores' terms: ``named``
    (causes as effects, naming order), ``labels`` (as reported), ``roles`` {label: role},
    ``shares`` {label: share}, ``gap_significant``, ``remaining`` (the report's block, or the first
    gap's verdict when nothing is named and the report has none; ``source`` says which)."""
    cands = [c for c in rep.get("candidates", []) or [] if isinstance(c, Mapping)]
    has_roles = any("role" in c for c in cands)
    if rep.get("named") is not None:
        labels = [str(x) for x in rep["named"]]
    else:
        labels = [str(c["effect"]) for c in cands if c.get("role") == "cause"]
    roles = ({str(c["effect"]): c.get("role") for c in cands} if has_roles
             else {label: "cause" for label in labels})
    shares = {str(c["effect"]): c.get("share", c.get("shrinkage")) for c in cands}
    gap = rep.get("gap", {}) or {}
    gap_sig = bool(gap.get("significant"))
    rem = rep.get("remaining")
    if isinstance(rem, Mapping):
        remaining = {k: rem.get(k) for k in ("chi2_per_dof", "significant", "unexplained_share")}
        remaining["cells"] = [dict(c) for c in rem.get("cells", []) or [] if c.get("significant", True)]
        remaining["source"] = "report"
    elif not labels:
        c2 = rep.get("chi2", {}) or {}
        cpd = c2["before"] / c2["dof_before"] if c2.get("dof_before") else gap.get("chi2_per_dof")
        remaining = {"chi2_per_dof": cpd, "significant": gap_sig,
                     "unexplained_share": 1.0 if gap_sig else None, "cells": [],
                     "source": "gap (nothing named)"}
    else:
        c2 = rep.get("chi2", {}) or {}
        cpd = c2["after"] / c2["dof_after"] if c2.get("dof_after") else None
        remaining = {"chi2_per_dof": cpd, "significant": None, "unexplained_share": None, "cells": [],
                     "source": "unknown (the report has no remaining block)"}
    return {"named": [effect_of(x) for x in labels], "labels": labels, "roles": roles, "shares": shares,
            "gap_significant": gap_sig, "remaining": remaining}


def run_case(payload: Mapping[str, Any]) -> dict[str, Any]:
    """One case (a task): ``payload`` has ``id``, ``family``, ``form``, ``effect``, ``seed`` and
    ``diagnose`` (options) and ``preset`` (default lumped). Returns the JSON-ready record
    :func:`score` reads."""
    from skinkit.gap.diagnose import diagnose

    t0 = time.perf_counter()
    rec: dict[str, Any] = {k: payload[k] for k in ("id", "family", "form", "effect", "accepted", "seed")}
    rec["name"] = payload["id"]
    preset = str(payload.get("preset", "lumped"))
    try:
        rec["visible_excess"] = visible_excess(payload["form"], preset)
        args = () if preset == "lumped" else (model_spec(preset),)
        rec["truth_info"] = _module(preset).truth(payload["form"], int(payload["seed"]), *args)["info"]
        obs = session(payload["form"], int(payload["seed"]), preset)
        td = time.perf_counter()
        opts = {"error_estimate": False, **dict(payload.get("diagnose", {}))}
        if KINDS[preset] == "fe":
            # the discretisation check would refine the mesh the truth shares with the model
            opts.setdefault("model_error", False)
        rep = diagnose(model_spec(preset), obs, free=free(preset), workers=1, **opts).to_dict()
        rec["diagnose_s"] = time.perf_counter() - td
        rec.update(reading(rep))
        rec["messages"] = list(rep.get("messages", []) or [])
    except SkinkitError as exc:
        rec["error"] = str(exc)
    rec["wall_s"] = time.perf_counter() - t0
    return rec


# -- scores -------------------------------------------------------------------------------------------
def _rate(k: int, n: int) -> dict[str, Any]:
    return {"k": int(k), "n": int(n), "rate": (k / n) if n else None, "interval_95": clopper_pearson(k, n)}


def verdict(rec: Mapping[str, Any]) -> dict[str, Any]:
    """One case judged: ``right`` (the family's right answer), and the parts the scores count."""
    named, rem = list(rec.get("named", [])), rec.get("remaining", {}) or {}
    if rec["family"] == "effect":
        accepted = set(rec.get("accepted") or [rec["effect"]])
        top1 = bool(named) and named[0] in accepted
        spurious = any(n not in accepted for n in named)
        return {"top1": top1, "spurious": spurious, "right": top1 and not spurious}
    if rec["family"] == "null":
        alarm = bool(named)
        sig = bool(rec.get("gap_significant")) or bool(rem.get("significant"))
        return {"false_alarm": alarm, "gap_significant": sig, "right": not alarm}
    recalled = not named and rem.get("significant") is True
    return {"recalled": recalled, "right": recalled}


def score(records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The figures of the case ``records`` of :func:`run_case` (module docstring), JSON-ready."""
    ok = [r for r in records if "error" not in r]
    fam = {f: [(r, verdict(r)) for r in ok if r["family"] == f] for f in ("effect", "null", "out-of-library")}
    out: dict[str, Any] = {}

    def put(key: str, rate_key: str, family: str, part: str) -> None:
        sel = fam[family]
        out[key] = _rate(sum(v[part] for _, v in sel), len(sel))
        out[rate_key] = out[key]["rate"]

    put("top1", "top1_accuracy", "effect", "top1")
    put("spurious", "spurious_rate", "effect", "spurious")
    put("null_false_alarm", "null_false_alarm_rate", "null", "false_alarm")
    put("null_gap_significant", "null_gap_significant_rate", "null", "gap_significant")
    put("unexplained", "unexplained_recall", "out-of-library", "recalled")
    confusion: dict[str, dict[str, int]] = {}
    by_form: dict[str, dict[str, Any]] = {}
    for r in ok:
        got = "+".join(r["named"]) or "none"
        row = confusion.setdefault(r["form"], {})
        row[got] = row.get(got, 0) + 1
        visible = (r.get("visible_excess") or {}).get("multiple")
        f = by_form.setdefault(r["form"], {"family": r["family"], "accepted": r.get("accepted", []),
                                           "cases": 0, "right": 0, "visible_multiple": visible})
        f["cases"] += 1
        f["right"] += bool(verdict(r)["right"])
    out["confusion"] = confusion
    out["by_form"] = by_form
    walls = [r["wall_s"] for r in records]
    out["case_wall_s"] = {"median": float(np.median(walls)) if walls else None,
                          "max": float(np.max(walls)) if walls else None}
    out["failed"] = [{"id": r["id"], "error": r["error"]} for r in records if "error" in r]
    return out


# -- running ----------------------------------------------------------------------------------------------
def run(quick: bool, *, seeds: int | None = None, forms_: Sequence[str] | None = None,
        parallel: int | None = None, scheduler: str | None = None,
        journal: str | os.PathLike[str] | None = None, recorded_only: bool = False,
        progress: Callable[[str], None] | None = None, max_effects: int | None = None,
        candidates: int | None = None, preset: str = "lumped") -> dict[str, Any]:
    """Run the alternative benchmark and score it (JSON-ready; keys in :func:`score`, plus
    ``cases``, ``forms``, ``skipped``, ``wall_s``).

    ``quick``: one seed per form and the quick diagnosis options (one effect named at most, two
    refits per round); otherwise :data:`FULL_SEEDS` seeds and the full options. ``forms_``: only
    these forms. ``parallel`` worker processes (default 2; 1 runs here) or a Dask ``scheduler``;
    ``journal``: record each case as it finishes and skip those it holds (as the withheld-effect
    benchmark's, :mod:`skinkit.bench.gap_journal`); ``recorded_only``: score the planned cases the
    journal holds, run nothing. ``progress(line)``: one line per case. ``preset``: the model the
    truths are written for (:data:`PRESETS`: ``"lumped"``, or ``"quick"``, the finite-element
    one, :mod:`skinkit.lab.alternative_fe`)."""
    from skinkit.forward.visibility import applicable_effects

    t0 = time.perf_counter()
    say = progress or (lambda line: None)
    kind = KINDS[_check(preset)]
    spec, names = model_spec(preset), free(preset)
    selected, skipped = coverage(forms(forms_, preset), applicable_effects(kind), preset)
    seeds = (QUICK_SEEDS if quick else FULL_SEEDS) if seeds is None else int(seeds)
    base_opts = QUICK_DIAGNOSE if quick else FULL_DIAGNOSE
    opts = {"max_effects": base_opts["max_effects"] if max_effects is None else int(max_effects),
            "candidates": base_opts["candidates"] if candidates is None else int(candidates)}
    if recorded_only and journal is None:
        raise BenchmarkError("--recorded-only scores a journal's cases: give --journal FILE")
    if recorded_only and not Path(journal).is_file():
        raise BenchmarkError(f"--recorded-only: journal {journal} does not exist")
    described = {f.name: {"family": f.family, "accepted": list(f.accepted), "description": f.description}
                 for f in selected}
    settings = {"benchmark": "alternative", "definitions": DEFINITIONS, "model": spec, "free": names,
                "diagnose": opts, "alpha": ALPHA, "forms": described}
    jr = _open_journal(journal, settings, say, read_only=recorded_only)
    cases = plan(selected, seeds)
    payloads = [dict(c, diagnose=opts, preset=preset) for c in cases]
    known = {} if jr is None else jr.cases
    before = {p["id"]: known[p["id"]] for p in payloads if p["id"] in known}
    todo = [] if recorded_only else [p for p in payloads if p["id"] not in before]
    if before:
        say(f"{len(before)} of {len(payloads)} cases from the journal, {len(todo)} to run")
    count = [len(before)]

    def case_line(r: Mapping[str, Any]) -> None:
        count[0] += 1
        if "error" in r:
            what = f"error: {r['error']}"
        else:
            rem = r["remaining"].get("significant")
            what = f"named {', '.join(r['named']) or 'none'}, remainder significant {rem}"
        say(f"case {count[0]}/{len(payloads)} {r['id']}: {what}, {r['wall_s']:.1f} s")
        if jr is not None:
            jr.add_case(r)

    pool = TaskPool(1 if recorded_only else (2 if parallel is None else int(parallel)), scheduler)
    try:
        fresh = {r["id"]: r for r in pool.map(run_case, todo, case_line)}
    finally:
        pool.close()
    done = {**before, **fresh}
    records = [done[p["id"]] for p in payloads if p["id"] in done]
    out = score(records)
    out.update({"model": spec.get("model", {}).get("name"), "preset": preset, "kind": kind, "free": names,
                "quick": bool(quick), "seeds": seeds, "diagnose_options": opts, "alpha": ALPHA,
                "forms": described, "skipped": skipped, "cases": records,
                "planned_cases": len(payloads), "resumed_cases": len(before),
                "wall_s": time.perf_counter() - t0})
    return out


def summary_lines(res: Mapping[str, Any]) -> list[str]:
    """The run's figures as the lines ``skinkit gap benchmark --alternative`` prints."""
    def pct(r: Mapping[str, Any]) -> str:
        if not r["n"]:
            return "-"
        lo, hi = r["interval_95"]
        return f"{100 * r['rate']:.0f} % ({r['k']}/{r['n']}; 95 % CI {100 * lo:.0f}-{100 * hi:.0f} %)"

    lines = [f"alternative truths on {res['model']} ({res.get('kind', 'lumped')}), {len(res['cases'])} of "
             f"{res['planned_cases']} planned cases, {res['wall_s'] / 60:.1f} min",
             f"top-1 attribution (effect cases): {pct(res['top1'])}",
             f"spurious causes (effect cases): {pct(res['spurious'])}",
             f"false alarms on null sessions: {pct(res['null_false_alarm'])}",
             f"'significant gap' on null sessions: {pct(res['null_gap_significant'])}",
             f"out-of-library reported unexplained: {pct(res['unexplained'])}",
             f"time per case: median {res['case_wall_s']['median'] or 0:.1f} s, "
             f"max {res['case_wall_s']['max'] or 0:.1f} s"]
    grouped: dict[str, list[str]] = {}
    for e, why in res["skipped"].items():
        grouped.setdefault(why, []).append(e)
    for why, names in grouped.items():
        lines.append(f"left out {', '.join(names)}: {why}")
    for f in res["failed"]:
        lines.append(f"failed {f['id']}: {f['error']}")
    lines.append("by form (right / cases; named):")
    for name, f in res["by_form"].items():
        mult = f.get("visible_multiple")
        vis = "" if mult is None or not math.isfinite(mult) else f", visible {mult:.0f}x threshold"
        row = sorted(res["confusion"][name].items(), key=lambda kv: -kv[1])
        named = ", ".join(f"{k} {v}" for k, v in row)
        lines.append(f"  {f['family']}/{name} ({' or '.join(f['accepted']) or 'nothing'}{vis}): "
                     f"{f['right']}/{f['cases']}; {named}")
    return lines


__all__ = ["DEFINITIONS", "FREE", "FULL_SEEDS", "KINDS", "PRESETS", "QUICK_SEEDS", "effect_of", "forms",
           "free", "model_spec", "plan", "reading", "run", "run_case", "score", "summary_lines", "verdict",
           "visible_excess"]
