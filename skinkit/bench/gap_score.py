"""Scores of the withheld-effect benchmark (:mod:`skinkit.bench.gap_cases` has the rules):
confusion, top-1 attribution, false alarms, localisation, magnitude and shrinkage errors,
with Clopper–Pearson intervals."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from skinkit.bench.gap_cases import ALPHA, LOCAL_AXES, MAGNITUDES, plugin_values, shrinkage


# -- scores -------------------------------------------------------------------------------------
def clopper_pearson(k: int, n: int, mass: float = 0.95) -> list[float] | None:
    """Exact central ``mass`` interval of a binomial proportion k/n (None when n = 0)."""
    from scipy.stats import beta

    if n <= 0:
        return None
    a = (1 - mass) / 2
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a, k + 1, n - k))
    return [lo, hi]


def _rate(k: int, n: int) -> dict[str, Any]:
    return {"k": k, "n": n, "rate": (k / n) if n else None, "interval_95": clopper_pearson(k, n)}


def _candidate(rep: Mapping[str, Any], name: str) -> dict[str, Any] | None:
    for c in rep.get("candidates", []):
        if c.get("effect") == name:
            return c
    for r in rep.get("rounds", []) or []:
        for c in (r.get("candidates", []) if isinstance(r, dict) else []):
            if c.get("effect") == name:
                return c
    return None


def _top_cell(rep: Mapping[str, Any]) -> dict[str, Any] | None:
    """The diagnosis's top-ranked significant cell on :data:`LOCAL_AXES` (largest share), in a
    partition of more than one cell (a one-cell partition, e.g. the only protocol, says nothing)."""
    cells = [c for c in rep["gap"]["cells"] if c.get("significant") and c.get("axis") in LOCAL_AXES
             and c.get("partition_size", 2) > 1]
    if not cells:
        return None
    return max(cells, key=lambda c: (c.get("share") or 0.0, c.get("chi2_per_dof") or 0.0))


def _label_numbers(label: str) -> list[float]:
    import re

    return [float(x) for x in re.findall(r"-?\d+(?:\.\d+)?", label)]


def _in_cells(cell: Mapping[str, Any], true_cells: Mapping[str, list[str]]) -> bool:
    """Is the diagnosis's ``cell`` one of the truth's occupied cells? Region labels are matched
    by their numbers when the edges differ by rounding (measured against exact references)."""
    axis, label = cell["axis"], cell["label"]
    keys = [k for k in true_cells if k.split("/")[0] == axis]
    if any(label in true_cells[k] for k in keys):
        return True
    if axis != "region":
        return False
    nums = _label_numbers(label)
    word = label.split(" ")[0]
    for k in keys:
        for t in true_cells[k]:
            tn = _label_numbers(t)
            if t.split(" ")[0] == word and len(tn) == len(nums) and np.allclose(tn, nums, atol=0.15):
                return True
    return False


def _main_parameter(rec: Mapping[str, Any], effect: str) -> str | None:
    """The scaled parameter of ``effect`` the oracle determines best (largest |true − null|/se)."""
    _, null, _ = plugin_values(effect)
    se = rec.get("oracle", {}).get("se", {})
    best, score_ = None, -1.0
    for k, v in rec["truth_parameters"].items():
        eff, _, local = k.partition(".")
        if eff != effect or abs(v - null.get(local, v)) == 0:
            continue
        s = se.get(k, math.nan)
        sc = abs(v - null[local]) / s if (s and math.isfinite(s) and s > 0) else 0.0
        if sc > score_:
            best, score_ = k, sc
    return best


def _estimate(cand: Mapping[str, Any] | None, full: str) -> float | None:
    pars = (cand or {}).get("parameters") or {}
    local = full.partition(".")[2]
    for key in (full, local):
        if key in pars:
            v = pars[key]
            v = v.get("value") if isinstance(v, Mapping) else v
            return None if v is None else float(v)
    return None


def assess(rec: Mapping[str, Any]) -> dict[str, Any]:
    """One case's verdicts: attribution, reported set, false alarm, localisation, magnitude and
    shrinkage errors (JSON-ready; missing when not applicable)."""
    out: dict[str, Any] = {}
    if "error" in rec:
        return {"failed": True}
    rep = rec["report"]
    named = list(rep["named"])
    truth = list(rec["truth"])
    out["named"] = named
    if not truth:
        out["false_alarm"] = bool(named)
        out["gap_significant"] = bool((rep.get("gap") or {}).get("significant"))
        return out
    first = named[0] if named else None
    reported = [first, *((_candidate(rep, first) or {}).get("not_separable_from") or [])] if first else []
    true_cand = _candidate(rep, truth[0]) or {}
    separable = (len(reported) <= 1) if first else not (true_cand.get("not_separable_from") or [])
    out["separable"] = separable
    out["reported_set"] = reported
    orc, c2 = rec.get("oracle"), rep.get("chi2") or {}
    if orc and c2.get("before") is not None:
        # what the true structure gains over the fitted model on this session: when not even
        # the oracle's refit improves χ² beyond noise, the session does not show the effect (the
        # model's own parameters express it), and no diagnosis could attribute it
        from scipy.stats import chi2 as chi2_dist

        k = int(round(float(c2["dof_before"]) - float(orc["dof"])))
        gain = float(c2["before"]) - float(orc["chi2"])
        out["oracle_gain"] = {"chi2": gain, "dof": k}
        out["visible"] = not (k > 0 and gain <= float(chi2_dist.ppf(1 - ALPHA, k)))
    if rec["kind"] == "effect":
        out["top1"] = first == truth[0]
        out["in_set"] = truth[0] in reported and len(reported) <= 2
    else:
        out["all_named"] = set(truth) <= set(named)
        out["any_named"] = bool(set(truth) & set(named))
    top = _top_cell(rep)
    if top is not None:
        out["top_cell"] = f"{top['axis']}: {top['label']}"
        out["localised"] = _in_cells(top, rec.get("true_cells", {}))
        part = f"{top['axis']}/{top.get('partition') or top['axis']}"
        occupied = rec.get("true_cells", {}).get(part)
        if occupied is not None and top.get("partition_size"):
            # the hit rate of a cell drawn at random from the partition: the metric's chance level
            out["localisation_chance"] = len(occupied) / top["partition_size"]
    if rec["kind"] == "effect" and first == truth[0]:
        main = _main_parameter(rec, truth[0])
        if main is not None:
            _, null, _ = plugin_values(truth[0])
            true = rec["truth_parameters"][main]
            est = _estimate(true_cand, main)
            if est is not None:
                d = true - null[main.partition(".")[2]]
                out["magnitude"] = {"parameter": main, "truth": true, "estimate": est,
                                    "relative_error": (est - true) / d}
    shr = (rep.get("shrinkage") or {}).get("overall")
    orc = rec.get("oracle")
    c2 = rep.get("chi2") or {}
    if named and shr is not None and orc and c2.get("before") is not None:
        oracle = shrinkage(float(c2["before"]), float(c2["dof_before"]), orc["chi2"], orc["dof"])
        if math.isfinite(oracle) and oracle > 0:
            out["shrinkage"] = {"reported": float(shr), "oracle": oracle,
                                "relative_error": (float(shr) - oracle) / oracle}
            if c2.get("after") is not None:
                # both clip to 1 once refit and oracle reach the noise, which hides how close the
                # refit came to the oracle; the unclipped pair still tells them apart
                args = (float(c2["before"]), float(c2["dof_before"]))
                rep_u = shrinkage(*args, float(c2["after"]), float(c2["dof_after"]), clip=False)
                orc_u = shrinkage(*args, orc["chi2"], orc["dof"], clip=False)
                out["shrinkage"].update(reported_unclipped=rep_u, oracle_unclipped=orc_u,
                                        unclipped_error=(rep_u - orc_u) / orc_u)
    return out


def score(records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The benchmark's figures from the case records of :func:`run_case` (JSON-ready)."""
    verdicts = [assess(r) for r in records]
    confusion: dict[str, dict[str, int]] = {}
    for r, v in zip(records, verdicts, strict=True):
        if v.get("failed"):
            continue
        key = "+".join(sorted(r["truth"])) or "none"
        if r["kind"] == "pair":
            got = "+".join(sorted(v["named"])) or "none"
        else:
            got = v["named"][0] if v["named"] else "none"
        row = confusion.setdefault(key, {})
        row[got] = row.get(got, 0) + 1

    def pick(kind: str, magnitude: str | None = None) -> list[tuple[Mapping[str, Any], dict[str, Any]]]:
        # cases whose session did not show the effect (``visible`` false) are counted apart
        return [(r, v) for r, v in zip(records, verdicts, strict=True)
                if r["kind"] == kind and not v.get("failed") and v.get("visible", True)
                and (magnitude is None or r["magnitude"] == magnitude)]

    out: dict[str, Any] = {}
    by_mag: dict[str, Any] = {}
    for mag in MAGNITUDES:
        sel = pick("effect", mag)
        sep = [v for _, v in sel if v["separable"]]
        non = [v for _, v in sel if not v["separable"]]
        by_mag[mag] = {"cases": len(sel),
                       "top1": _rate(sum(v["top1"] for v in sep), len(sep)),
                       "in_reported_set": _rate(sum(v["in_set"] for v in non), len(non)),
                       "named_any": _rate(sum(bool(v["named"]) for _, v in sel), len(sel))}
    mod = by_mag["moderate"]
    out["top1_accuracy"] = mod["top1"]["rate"]
    out["top1"] = mod["top1"]
    out["not_separable_in_set_rate"] = mod["in_reported_set"]["rate"]
    out["by_magnitude"] = by_mag
    nulls = pick("null")
    fa = _rate(sum(v["false_alarm"] for _, v in nulls), len(nulls))
    out["null_false_alarm_rate"] = fa["rate"]
    out["null_false_alarm"] = fa
    # the report's "significant gap" on sessions the model describes: its gate's level, ALPHA
    out["null_gap_significant"] = _rate(sum(v["gap_significant"] for _, v in nulls), len(nulls))
    pairs = pick("pair")
    out["pairs"] = {"both_named": _rate(sum(v["all_named"] for _, v in pairs), len(pairs)),
                    "one_named": _rate(sum(v["any_named"] for _, v in pairs), len(pairs))}
    loc = [v for kind in ("effect", "pair") for _, v in pick(kind) if "localised" in v]
    out["localisation"] = _rate(sum(v["localised"] for v in loc), len(loc))
    out["localisation_accuracy"] = out["localisation"]["rate"]
    chance = [v["localisation_chance"] for v in loc if "localisation_chance" in v]
    out["localisation"]["chance_mean"] = float(np.mean(chance)) if chance else None
    out["localisation"]["no_significant_cell"] = sum(
        1 for kind in ("effect", "pair") for _, v in pick(kind) if "localised" not in v)
    mags = [abs(v["magnitude"]["relative_error"]) for _, v in pick("effect", "moderate") if "magnitude" in v]
    out["magnitude_error_median"] = float(np.median(mags)) if mags else None
    out["magnitude_errors"] = {"n": len(mags), "within_15_percent": sum(m <= 0.15 for m in mags)}
    shr = [abs(v["shrinkage"]["relative_error"]) for _, v in pick("effect", "moderate") if "shrinkage" in v]
    out["shrinkage_error_median"] = float(np.median(shr)) if shr else None
    out["shrinkage_errors"] = {"n": len(shr), "within_15_percent": sum(s <= 0.15 for s in shr)}
    shr_u = [abs(v["shrinkage"]["unclipped_error"]) for _, v in pick("effect", "moderate")
             if "unclipped_error" in v.get("shrinkage", {})]
    out["shrinkage_errors"].update(unclipped_median=float(np.median(shr_u)) if shr_u else None,
                                   unclipped_max=float(np.max(shr_u)) if shr_u else None)
    out["confusion"] = confusion
    out["not_visible"] = [{"id": r["id"], "named": v["named"], "oracle_gain": v["oracle_gain"]}
                          for r, v in zip(records, verdicts, strict=True)
                          if not v.get("failed") and v.get("visible") is False]
    walls = [r["wall_s"] for r in records]
    out["case_wall_s"] = {"median": float(np.median(walls)) if walls else None,
                          "max": float(np.max(walls)) if walls else None}
    out["failed"] = [{"id": r["id"], "error": r["error"]} for r in records if "error" in r]
    out["verdicts"] = {r["id"]: v for r, v in zip(records, verdicts, strict=True)}
    return out

