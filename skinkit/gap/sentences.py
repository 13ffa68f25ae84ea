"""The gap verdict in plain sentences, from the report's own numbers (the final model's).

Every number a sentence quotes comes from the dict the JSON holds (``candidates`` with their
final ``parameters``, ``share`` and ``role``; ``remaining``; ``warnings``), so that stdout, the
HTML page and the JSON cannot disagree.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from skinkit.gap.score import ABSORBED
from skinkit.gap.verdict import noise_sentence, remaining_sentence
from skinkit.units import unit_suffix

#: the pre-stress effect's parameter names (the fitter's: stretches along and across ``angle``)
PRESTRESS_KEYS = ("l1", "l2", "angle")


def num(x: Any) -> float | None:
    """``x`` as a finite float, or None."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def disc_messages(disc: Mapping[str, Any] | None) -> list[str]:
    """The discretisation check's sentences (none when it was not made)."""
    if disc is None:
        return []
    frac = disc.get("explained_by_signature")
    share = (
        ""
        if frac is None
        else (
            f"; along its signature, at any size, a finer mesh would remove {100 * frac:.0f} % of the excess"
        )
    )
    out = [
        f"Discretisation (mesh refined {disc['factor']}x, {disc['unknowns']:,} -> "
        f"{disc['unknowns_refined']:,} unknowns): the error alone is χ² "
        f"{disc['chi2_discretisation']:.4g} against ν {disc['dof']}{share}."
    ]
    if disc.get("explains"):
        out.append(
            f"Not named, because discretisation explains the residual along their signatures: "
            f"{', '.join(disc['explains'])}."
        )
    return out


def prestress_display(l1: float, l2: float, angle_rad: float) -> tuple[float, float, float]:
    """The pre-stretch as the reports show it, ``(λ1, λ2, θ)`` [1, 1, deg]: the stretches ordered
    λ1 ≥ λ2 and θ the direction of λ1 from the x axis, folded into (−90°, 90°] (as the virtual
    lab writes its truth). The fitter's ``(l1, l2, angle [rad])`` may have l2 > l1 or any angle:
    the same state then reads differently, so every report converts through this one function."""
    if l2 > l1:   # l2 acts along angle + 90°
        l1, l2, angle_rad = l2, l1, angle_rad + math.pi / 2
    deg = math.degrees(angle_rad) % 180.0   # a stretch direction is an axis: θ and θ + 180° agree
    return l1, l2, deg - 180.0 if deg > 90.0 else deg


def _prestress_groups(names: Sequence[str]) -> list[str]:
    """The prefixes (``"prestress."``, ``"skin.prestretch."``, ``""``) under which all three
    pre-stress names :data:`PRESTRESS_KEYS` are present."""
    return [pre for pre in dict.fromkeys(n[: -len(k)] for n in names for k in PRESTRESS_KEYS if n.endswith(k))
            if all(pre + k in names for k in PRESTRESS_KEYS) and (pre == "" or pre.endswith("."))]


def display_parameters(pars: Mapping[str, Any]) -> dict[str, Any]:
    """``pars`` (name -> value, or name -> ``{"value", "se", "unit"}`` with values in SI) with
    each pre-stress triple ``l1, l2, angle`` shown as ``λ1, λ2, θ`` of :func:`prestress_display`
    (θ in degrees, unit ``"°"``; the standard errors follow their stretch, the angle's in
    degrees); every other entry unchanged, in order. Only for display: the raw values stay in
    the JSON as the fitter named them."""
    out: dict[str, Any] = dict(pars)
    for pre in _prestress_groups(list(pars)):
        raw = [pars[pre + k] for k in PRESTRESS_KEYS]
        vals = [num(r.get("value") if isinstance(r, Mapping) else r) for r in raw]
        if any(v is None for v in vals):
            continue
        l1, l2, deg = prestress_display(*vals)   # type: ignore[arg-type]
        swapped = vals[1] > vals[0]   # type: ignore[operator]
        shown: dict[str, Any] = {}
        for key, v, src, unit in (("λ1", l1, raw[1 if swapped else 0], "1"),
                                  ("λ2", l2, raw[0 if swapped else 1], "1"), ("θ", deg, raw[2], "°")):
            if isinstance(src, Mapping):
                se = num(src.get("se"))
                shown[pre + key] = {**src, "value": v, "unit": unit,
                                    "se": None if se is None else (math.degrees(se) if key == "θ" else se)}
            else:
                shown[pre + key] = v
        at = list(out).index(pre + PRESTRESS_KEYS[0])
        rest = [(n, x) for n, x in out.items() if n not in {pre + k for k in PRESTRESS_KEYS}]
        out = dict(rest[:at] + list(shown.items()) + rest[at:])
    return out


def parameter_text(pars: Mapping[str, Mapping[str, Any]]) -> str:
    """``"n = v ± 1.96 se unit, ..."`` (one interval per estimate; pre-stress as
    :func:`display_parameters` shows it)."""
    pars = display_parameters(pars)
    return ", ".join(
        f"{n} = {v['value']:.4g}"
        + (f" ± {1.96 * v['se']:.2g}" if v.get("se") else "")
        + unit_suffix(v.get("unit"))
        for n, v in pars.items()
    )


def added_messages(
    candidates: Sequence[Mapping[str, Any]], added: Sequence[str], min_share: float
) -> list[str]:
    """One sentence per effect added to the model, cause or minor, with its final values."""
    out = []
    for lab in added:
        c = next((c for c in candidates if c["effect"] == lab), None)
        if c is None:
            continue
        share = c.get("share")
        removed = (
            "removes no part of the excess (there was none as a whole)"
            if share is None
            else f"removes {100 * share:.0f} % of the excess the noise level cannot account for"
        )
        pars = parameter_text(c.get("parameters") or {})
        if c.get("role") == "cause":
            out.append(f"`{lab}` is a cause: it {removed} (ΔAIC {c['delta_aic']:.1f}; {pars}).")
        else:
            why = c.get("role_reason") or f"less than the {100 * min_share:.0f} % a cause needs"
            out.append(
                f"`{lab}` is a minor contribution, not a cause: it {removed}, {why} "
                f"(ΔAIC {c['delta_aic']:.1f}; {pars})."
            )
    return out


def _location(loc: Any) -> list[str]:
    where = []
    ranked = [c for c in loc.ranked() if c.share > 0]
    for axis in ("protocol", "channel", "phase", "region", "frequency"):
        cells = [c for c in ranked if c.axis == axis][:2]
        if cells:
            where.append(", ".join(f"{c.label} ({100 * c.share:.0f} % of the excess)" for c in cells))
    return where


def model_error_messages(err: Mapping[str, Any] | None) -> list[str]:
    """The model's mesh error carried as noise (:mod:`skinkit.inverse.approximation`): its size per
    channel against the noise, what share of the calibration's excess it accounts for, and when
    it is the largest term, which refinement would bring it below the noise."""
    if not err:
        return []
    parts = [f"{c} {row['rms_over_noise']:.3g}" for c, row in err.get("channels", {}).items()
             if row.get("rms_over_noise") is not None]
    share = err.get("accounts_for")
    text = (f"Model error (mesh of {err.get('unknowns', 0):,} unknowns against one refined "
            f"{err.get('factor', 2)}x): {', '.join(parts) or 'none'} noise levels RMS, carried as noise")
    text += "." if share is None else f"; it accounts for {100 * share:.0f} % of the calibration's excess."
    out = [text]
    if share is not None and share >= 0.5:
        ref = err.get("refine_to_noise", {})
        out.append(f"The mesh, not the physics, is the largest term of the gap: a mesh about "
                   f"{ref.get('order_2', 1):.2g}x (convergence order 2) to {ref.get('order_1', 1):.2g}x "
                   "(order 1) finer along each axis would bring its error below the noise.")
    return out


def final_mesh_messages(err: Mapping[str, Any] | None) -> list[str]:
    """What the final model's mesh cannot render: its estimate's ``resolution`` names the free
    parameters whose signature the model's mesh misrepresents by more than
    :data:`skinkit.inverse.approximation.RESOLUTION_LIMIT`."""
    from skinkit.inverse.approximation import RESOLUTION_LIMIT, unresolved

    res = (err or {}).get("resolution") or {}
    over = unresolved(res)
    if not over:
        return []
    listed = ", ".join(f"{n} ({res[n]:.2g})" if res[n] is not None and math.isfinite(res[n])
                       else f"{n} (only the refined mesh sees it)" for n in over)
    one = len(over) == 1
    return [f"Warning: the model's mesh ({err.get('unknowns', 0):,} unknowns) cannot render what "
            f"{listed} {'does' if one else 'do'}: the refined mesh's signature differs from "
            f"its own by more than {RESOLUTION_LIMIT:g} of it, so {'its' if one else 'their'} "
            f"fitted value{'' if one else 's'} and interval{'' if one else 's'} are the "
            f"mesh's more than the skin's; a mesh refined {err.get('factor', 2)}x "
            f"({err.get('unknowns_refined', 0):,} unknowns) renders {'it' if one else 'them'}."]


def periodic_sentence(lines: Sequence[Any], chi2_per_dof: float, elsewhere: bool) -> str:
    """The periodic components of the residual (:class:`skinkit.gap.lines.Line`) in words;
    ``elsewhere``: whether the residual's χ² shows a gap besides them."""
    from skinkit.gap.lines import describe

    text = (f"Periodic component{'s' if len(lines) > 1 else ''} above ten times the drive's band, which "
            f"the noise model does not hold: {describe(list(lines))} — a tone from outside the skin "
            "(mains pick-up, a vibration)? No installed effect models a tone")
    if not elsewhere:
        text += (f"; the residual's χ²/ν ({chi2_per_dof:.3g}) does not show it because the noise "
                 "model, estimated on the rest segment, took the tone in")
    return text + "."


def messages(
    report: Mapping[str, Any],
    loc: Any,
    gap: Mapping[str, Any],
    chi2_per_dof: float,
    added: Sequence[str],
    min_share: float,
    tests_significant: Sequence[str],
    refit_any: bool,
) -> list[str]:
    """The verdict: noise, gap and where, each added effect, the remainder, separation, warnings.

    ``report``: the JSON-ready report so far (``candidates``, ``remaining``, ``warnings``,
    ``noise``, ``separation``, ``discretisation``); ``loc``: the first round's location;
    ``gap``: the first round's gate; ``added``: labels added to the model, in order;
    ``tests_significant``: candidates whose score test survived the correction in round 1;
    ``refit_any``: whether any candidate was refitted."""
    out = disc_messages(report.get("discretisation"))
    ns = noise_sentence(report.get("noise") or {})
    if ns:
        out.append(ns)
    out += model_error_messages(report.get("model_error"))
    if not gap.get("significant", loc.significant):
        out.append(f"No significant gap: χ²/ν {chi2_per_dof:.3g} is at the noise level; no effect named.")
        return out + [f"Warning: {w['message']}." for w in report.get("warnings", [])]
    ranked = [c for c in loc.ranked() if c.share > 0]
    lines = list(getattr(loc, "lines", []) or [])
    if lines:
        out.append(periodic_sentence(lines, chi2_per_dof, bool(ranked)))
    if not gap.get("omnibus_significant", True) and not ranked:
        top = next((c for c in report["candidates"] if c["effect"] in gap.get("directed", [])), None)
        out.append(
            f"No gap in the residual as a whole (χ²/ν {chi2_per_dof:.3g} is within the noise), but the "
            f"score test finds one along {top['effect'] if top else 'a candidate'}'s signature"
            + (f" (LM {top['score']:.3g}, p {top['p_value']:.2g})." if top else ".")
        )
    elif ranked or not lines:
        where = _location(loc)
        out.append(
            f"Significant gap: χ²/ν {chi2_per_dof:.3g}"
            + (f"; located in {'; '.join(where)}." if where else ".")
        )
    out += added_messages(report["candidates"], added, min_share)
    out += final_mesh_messages(report.get("final_model_error"))
    if not added:
        if tests_significant and not refit_any:
            out.append(
                f"The score tests of {', '.join(tests_significant)} are significant, but no candidate was "
                "refitted (--max-effects 0, or every refit failed): nothing can be named."
            )
        elif not tests_significant:
            out.append("No installed effect's score test is significant.")
        else:
            reasons = [f"{c['effect']}: {c['not_named']}" for c in report["candidates"] if c.get("not_named")]
            out.append("No effect added: " + "; ".join(reasons) + "." if reasons else "No effect added.")
    rem = report.get("remaining")
    if rem is not None:
        out.append(remaining_sentence(rem, added))
    for sp in report.get("separation", []):
        a, b = sp["effects"]
        if "protocol" in sp:
            out.append(
                f"{a} and {b} are not separable on these protocols (|cos| {sp['cosine']:.3f}); "
                f"{sp['protocol']} would separate them best (|cos| {sp['cosine_after']:.3f})."
            )
        else:
            out.append(f"{a} and {b} are not separable on these protocols (|cos| {sp['cosine']:.3f}).")
    # an added effect was judged by its refit, not its score test
    out += [resemble_sentence(c["effect"], r) for c in report["candidates"] if c["effect"] not in added
            for r in c.get("resembles") or []]
    out += [f"Warning: {w['message']}." for w in report.get("warnings", [])]
    return out


def resemble_sentence(effect: str, r: Mapping[str, Any]) -> str:
    """What a candidate's parameter the fitted ones all but absorb means (``r``: one entry of
    its ``resembles``, :func:`skinkit.gap.score.resemblance`)."""
    kept, cos = float(r["kept"]), float(r["cosine"])
    name = r["parameter"] if str(r["parameter"]).startswith(f"{effect}.") else f"{effect}'s {r['parameter']}"
    if kept < ABSORBED:
        # a column in the fitted span to rounding is a parameter the model already has
        what = (f"{r['fitted']} itself" if cos >= 0.999 else
                f"a combination of the fitted parameters (closest: {r['fitted']}, |cos| {cos:.3f})")
        return (f"{name} is {what} on these protocols: the model already fits it, so it was not "
                f"tested.")
    like = (f"its signature is that of {r['fitted']} (|cos| {cos:.3f})" if cos >= 0.9 else
            f"its signature is a combination of the fitted parameters' "
            f"(closest: {r['fitted']}, |cos| {cos:.2f})")
    return (f"{name} cannot be told from the fitted parameters on these protocols: {like}, "
            f"and {100 * kept:.2g} % of it is left once they are fitted, so its score test says little; "
            f"fix {r['fitted']} (or add a protocol that moves them apart) to test it.")


__all__ = ["PRESTRESS_KEYS", "added_messages", "disc_messages", "display_parameters", "messages", "num",
           "parameter_text", "prestress_display", "resemble_sentence"]
