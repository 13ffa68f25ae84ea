"""The honest verdict of a gap diagnosis: which added effects are causes, which minor, what
remains unexplained, and every failure or implausible answer stated.

* **share**: the fraction of the first model's excess an effect removes on its own: added alone
  to the calibrated model and refitted. Overlapping effects (relaxation and preconditioning both
  lower later peaks) are each judged by what they explain; a cause must also remove at least
  ``min_share`` of what the effects added before it left, so that an effect whose part another
  already took is not named beside it. Further instances of a repeatable effect ("more of the
  same": a second Prony term) count with the first: they add what they removed when they were
  added. The excess is χ² − κν, κ the residual's χ²/ν in the band where no effect acts
  (:func:`noise_factor`): on tens of thousands of samples a noise level off by a few per cent
  would otherwise outweigh every effect. An effect is a **cause** when its family's share
  reaches ``min_share`` (default :data:`MIN_SHARE`, half) and nothing undermines it (its refit
  did not converge, or one of its parameters sits on a bound); a **minor** contribution when it
  was added (significant score test, AIC and held-out rules met) with a smaller share;
  **rejected** otherwise. On tens of thousands of samples a useless parameter passes any AIC
  margin; the share is what separates "a cause was found" from "something was improved".
* **remaining**: the final model's residual located and tested again
  (:func:`skinkit.gap.where.locate`); when it is still significant, the fraction of the first
  model's excess left and the cells where it lies are reported: that part of the gap is not
  explained by any installed effect.
* **warnings**: a calibration or refit that did not converge, a refit the solver gave up on, a
  parameter on its bound, a model whose prediction over a rest segment misses the readings (an
  offset that took over part of the force), a pre-stretch below 1, a stop at ``max_effects``
  with a significant remainder.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from skinkit.inverse.fit import ON_BOUND, on_bound
from skinkit.schemas import Observations, Prediction

#: the share of the excess an effect must remove to be named as a cause
MIN_SHARE = 0.5
#: a significant remainder holding less than this share of the excess is called small
SMALL_REMAINDER = 0.05
#: samples the high band needs before its χ²/ν calibrates the noise level
FACTOR_MIN_DOF = 1000
#: a rest segment's mean residual beyond this many noise levels misses the readings
REST_MISS = 3.0


def family(label: str, known: Sequence[str]) -> str:
    """The effect a candidate label belongs to: ``"viscoelastic-2"`` -> ``"viscoelastic"`` when
    ``viscoelastic`` is one of ``known`` (the installed effects), else the label itself."""
    base, _, k = label.rpartition("-")
    return base if k.isdigit() and base in known else label


def noise_summary(observations: Observations) -> dict[str, Any]:
    """Per channel the noise model the diagnosis used: ``kind`` ("white" or "AR"), ``order``,
    ``sigma`` (marginal, of the component with most valid samples) [unit], ``innovation``,
    ``unit``, ``source`` and ``outliers`` (``count`` and the first ``times_s``)."""
    out: dict[str, Any] = {}
    for po in observations:
        for ch in po.channels.values():
            if ch.is_points:
                entry = out.setdefault(
                    ch.name,
                    {
                        "kind": "white",
                        "order": 0,
                        "sigma": float(np.max(ch.noise)),
                        "innovation": float(np.max(ch.noise)),
                        "unit": ch.unit,
                        "source": ch.noise_source,
                        "outliers": {"count": 0, "times_s": []},
                    },
                )
                continue
            j = int(np.argmax(ch.valid.sum(axis=0)))
            order = int(ch.noise_ar[j].size) if ch.noise_ar is not None else 0
            inn = ch.noise[j] if ch.noise_innovation is None else ch.noise_innovation[j]
            entry = out.setdefault(
                ch.name,
                {
                    "kind": "AR" if order else "white",
                    "order": order,
                    "sigma": float(ch.noise[j]),
                    "innovation": float(inn),
                    "unit": ch.unit,
                    "source": ch.noise_source,
                    "outliers": {"count": 0, "times_s": []},
                },
            )
            if ch.outliers is not None:
                rows = np.flatnonzero(ch.outliers.any(axis=1))
                entry["outliers"]["count"] += int(rows.size)
                entry["outliers"]["times_s"] += [round(float(ch.time_s[i]), 4) for i in rows[:20]]
    return out


def noise_sentence(noise: Mapping[str, Any]) -> str | None:
    """One sentence on the noise model of the force channel (or the first channel)."""
    if not noise:
        return None
    name = "tip_force" if "tip_force" in noise else next(iter(noise))
    n = noise[name]
    kind = f"AR({n['order']})" if n["kind"] == "AR" else "white"
    spikes = n["outliers"]["count"]
    tail = f"; {spikes} isolated spike(s) left out of every sum" if spikes else ""
    return (
        f"Noise of {name}: {kind}, σ {n['sigma']:.3g} {n['unit']} ({n['source'].split(';')[0]}){tail}; "
        "χ²/ν = 1 means the sensor's own noise, coloured as it is."
    )


def noise_factor(loc: Any) -> float:
    """κ: χ²/ν of the residual in the band above ten times the input's (where no effect of a
    model driven at the input's rates acts), when that band holds at least half the samples and
    :data:`FACTOR_MIN_DOF` of them; else 1. It measures how well the noise level is known: on
    tens of thousands of samples a level off by a few per cent is an excess of thousands, which
    no effect can remove and which would otherwise dwarf every effect's share."""
    total = sum(c.dof for c in loc.cells if c.axis == "frequency")
    hf = next((c for c in loc.cells if c.axis == "frequency" and c.label == "above 10x input band"), None)
    if hf is None or not (hf.dof >= FACTOR_MIN_DOF and hf.dof >= 0.5 * total):
        return 1.0
    return float(hf.chi2_per_dof)


def _excess(state: Mapping[str, Any], kappa: float = 1.0) -> float:
    """The excess the noise level cannot account for: χ² − κν."""
    return float(state["chi2"] - kappa * state["dof"])


def family_shares(
    additions: Sequence[Mapping[str, Any]],
    known: Sequence[str],
    kappa: float,
    alone: Mapping[str, float | None],
    chi2_first: float,
    dof_first: float,
) -> dict[str, float | None]:
    """Share of each added family (see module): what its first instance removes from the first
    model when added alone (``alone``: label -> that refit's χ², None: unknown, then what it
    removed when it was added), plus what its further instances removed when they were added,
    over the first model's excess χ² − κν (``kappa``: :func:`noise_factor`). ``additions`` in
    order, each ``{"effect", "before", "after"}`` (states with ``chi2``)."""
    e0 = float(chi2_first - kappa * dof_first)
    removed: dict[str, float] = {}
    for a in additions:
        f = family(a["effect"], known)
        step = float(a["before"]["chi2"] - a["after"]["chi2"])
        if f not in removed and alone.get(a["effect"]) is not None:
            step = float(chi2_first - alone[a["effect"]])
        removed[f] = removed.get(f, 0.0) + step
    return {f: (None if e0 <= 0 else float(np.clip(r / e0, 0.0, 1.0))) for f, r in removed.items()}


def _left_shares(
    additions: Sequence[Mapping[str, Any]], known: Sequence[str], kappa: float
) -> dict[str, float | None]:
    """Per added family, what its instances removed of the excess left when its first one was
    added (χ² − κν of that model; None when nothing was left)."""
    base: dict[str, float] = {}
    removed: dict[str, float] = {}
    for a in additions:
        f = family(a["effect"], known)
        base.setdefault(f, _excess(a["before"], kappa))
        removed[f] = removed.get(f, 0.0) + float(a["before"]["chi2"] - a["after"]["chi2"])
    return {f: (None if base[f] <= 0 else float(np.clip(removed[f] / base[f], 0.0, 1.0))) for f in base}


def assign_roles(
    candidates: Sequence[dict[str, Any]],
    additions: Sequence[Mapping[str, Any]],
    known: Sequence[str],
    min_share: float,
    undermined: Mapping[str, str],
    kappa: float = 1.0,
    *,
    alone: Mapping[str, float | None],
    chi2_first: float,
    dof_first: float,
) -> tuple[list[str], list[str]]:
    """Set ``role``, ``share`` and ``role_reason`` on every candidate dict; returns ``(causes,
    minor)`` (labels of added effects, in order). ``undermined``: added label -> why it cannot
    be a cause (a refit that did not converge, a parameter on its bound); the rest as
    :func:`family_shares`. A rejected candidate refitted against the first model gets the share
    that refit removed, on the same scale."""
    shares = family_shares(additions, known, kappa, alone, chi2_first, dof_first)
    e0 = float(chi2_first - kappa * dof_first)
    added = [a["effect"] for a in additions]
    left = _left_shares(additions, known, kappa)
    causes, minor = [], []
    why: dict[str, str] = {}
    for lab in added:
        f = family(lab, known)
        bad = [undermined[x] for x in added if family(x, known) == f and x in undermined]
        if bad:
            why[f] = "but " + "; ".join(bad)
        elif shares[f] is None or shares[f] < min_share:
            why[f] = f"less than the {_pct(min_share)} a cause needs"
        elif left[f] is None or left[f] < min_share:
            why[f] = (
                f"but of what the effects added before it left, it removes {_pct(left[f])}: "
                "what it explains was mostly explained already"
            )
        (minor if f in why else causes).append(lab)
    for c in candidates:
        lab = c["effect"]
        f = family(lab, known)
        if lab in added:
            c["share"] = shares[f]
            c["role"] = "cause" if lab in causes else "minor"
            if lab in minor:
                c["role_reason"] = why[f]
        else:
            refit = c.get("chi2_refit") if c.get("refitted") else None
            c["share"] = None if refit is None or e0 <= 0 else float(np.clip((chi2_first - refit) / e0, 0, 1))
            c["role"] = "rejected"
    return causes, minor


def _pct(x: float | None) -> str:
    return "no part" if x is None else f"{100 * x:.0f} %"


def remaining(
    loc: Any, final: Mapping[str, Any], state0: Mapping[str, Any], kappa: float = 1.0
) -> dict[str, Any]:
    """What the final model leaves: χ²/ν, whether it is still a significant gap, the fraction of
    the first model's excess (χ² − κν) left when it is, the significant cells that hold a share,
    and κ (``noise_factor``)."""
    sig = bool(loc.significant)
    e0, e1 = _excess(state0, kappa), _excess(final, kappa)
    share = float(np.clip(e1 / e0, 0.0, 1.0)) if (sig and e0 > 0) else (1.0 if sig else 0.0)
    cells = [
        {"axis": c.axis, "label": c.label, "share": float(c.share), "chi2_per_dof": float(c.chi2_per_dof)}
        for c in loc.ranked()
        if c.share > 0
    ]
    return {
        "chi2_per_dof": float(final["chi2"] / final["dof"]),
        "significant": sig,
        "unexplained_share": share,
        "cells": cells,
        "noise_factor": kappa,
        "lines": [ln.to_dict() for ln in getattr(loc, "lines", []) or []],
    }


def remaining_sentence(rem: Mapping[str, Any], added: Sequence[str]) -> str:
    """The remainder in words."""
    if not rem["significant"]:
        return f"The remainder is at the noise level (χ²/ν {rem['chi2_per_dof']:.3g}): the gap is " + (
            "explained by the effects added." if added else "not significant."
        )
    where = ", ".join(f"{c['label']} ({c['axis']}, χ²/ν {c['chi2_per_dof']:.3g})" for c in rem["cells"][:4])
    at = f" in {where}" if where else ""
    if rem.get("lines") and not rem["cells"]:
        from skinkit.gap.lines import Line, describe

        tones = describe([Line(**ln) for ln in rem["lines"]])
        return ("Part of the gap is not explained by any installed effect: the periodic components "
                f"({tones}) remain.")
    if rem["unexplained_share"] < SMALL_REMAINDER:
        return (
            f"The remainder is still significant{at}, but holds "
            f"{100 * rem['unexplained_share']:.0f} % of the first model's excess: no installed effect "
            "explains it, and it is small."
        )
    return (
        f"Part of the gap is not explained by any installed effect: {100 * rem['unexplained_share']:.0f} % "
        f"of the excess remains (χ²/ν {rem['chi2_per_dof']:.3g}){at}."
    )


def _warn(kind: str, message: str, **extra: Any) -> dict[str, Any]:
    return {"kind": kind, "message": message, **extra}


def fit_warnings(result: Any, what: str, names: Sequence[str]) -> list[dict[str, Any]]:
    """A fit that did not converge and parameters (of ``names``) on a bound."""
    out = []
    if not result.converged:
        out.append(
            _warn(
                "not-converged",
                f"{what} did not converge ({result.message or 'no message'}, "
                f"{result.n_forward} forward solves): its values are provisional",
                where=what,
            )
        )
    for n in names:
        p = result.parameters.param(n)
        side = on_bound(p)
        if side is not None:
            out.append(
                _warn(
                    "on-bound",
                    f"{what}: {n} = {p.value:.4g} sits on its {side} bound; its "
                    "interval means little and the data may want a value outside the range",
                    where=what,
                    parameter=n,
                )
            )
        if "stretch" in n and p.value < 1:
            out.append(
                _warn(
                    "prestretch-below-1",
                    f"{what}: {n} = {p.value:.4g} is below 1 (a compressed skin, not a pre-stretched one)",
                    where=what,
                    parameter=n,
                )
            )
    return out


def rest_warnings(observations: Observations, prediction: Prediction) -> list[dict[str, Any]]:
    """A prediction that misses the force readings over a protocol's rest segment (before the
    position first moves) by more than :data:`REST_MISS` noise levels."""
    from skinkit.forward.noise_model import rest_length

    out = []
    for name, cp in prediction.protocols.items():
        if name not in observations.protocols or "tip_force" not in cp:
            continue
        chans = observations[name].channels
        if "tip_position" not in chans:
            continue
        pos = chans["tip_position"]
        n = rest_length(np.where(pos.valid, pos.values, np.nan), pos.noise, np.zeros_like(pos.noise))
        if n < 20:
            continue
        ch = chans["tip_force"]
        m = ch.fit_mask(cp["tip_force"].predicted)[:n]
        for j in range(ch.values.shape[1]):
            if m[:, j].sum() < 10:
                continue
            miss = float(np.mean((cp["tip_force"].values[:n, j] - ch.values[:n, j])[m[:, j]]))
            if abs(miss) > REST_MISS * ch.noise[j]:
                out.append(
                    _warn(
                        "rest-readings-missed",
                        f"{name}: over the rest segment (first {n} samples) the model's tip force "
                        f"{'xyz'[j]} differs from the readings by {miss:.3g} N "
                        f"({abs(miss) / ch.noise[j]:.0f} noise levels): a fitted offset may have taken over "
                        "part of the force",
                        where=name,
                        value=miss,
                    )
                )
    return out


def colour_warnings(observations: Observations, prediction: Prediction,
                    significant: bool) -> list[dict[str, Any]]:
    """A significant gap on a tip channel whose noise level came from second differences alone
    (no rest segment before the motion to estimate the noise's colour from): that estimate assumes
    white noise, and a coloured sensor noise reads low there (AR(1) with φ 0.9: a quarter of its
    marginal level), so what is reported as a gap may be the sensor's own noise. One warning per
    predicted channel (a drive is not in the residual), naming its protocols."""
    from skinkit.forward.noise_model import samples_needed
    from skinkit.forward.observations import SECOND_DIFFERENCES

    if not significant:
        return []
    where: dict[str, list[str]] = {}
    for po in observations:
        predicted = prediction.protocols.get(po.protocol.name, {})
        for ch in po.channels.values():
            if ch.name not in predicted or ch.is_points or ch.noise_ar is not None \
                    or ch.noise_source != SECOND_DIFFERENCES:
                continue
            where.setdefault(ch.name, []).append(po.protocol.name)
    return [_warn("noise-colour-unknown",
                  f"{name}: no rest segment in {', '.join(protos)} to estimate the noise's colour from; its "
                  "level comes from second differences, which assume white noise, and a coloured sensor "
                  "noise reads low there (AR(1) with φ 0.9: a quarter of its level), so part of the gap "
                  f"may be the sensor's own noise: record at least {samples_needed(1)} samples at rest "
                  "before the motion", where=name)
            for name, protos in where.items()]


def record_warnings(observations: Observations, prediction: Prediction,
                    significant: bool) -> list[dict[str, Any]]:
    """What the records themselves put in doubt: :func:`rest_warnings` and, when the remainder is
    ``significant``, :func:`colour_warnings`."""
    return rest_warnings(observations, prediction) + colour_warnings(observations, prediction, significant)


__all__ = [
    "colour_warnings",
    "noise_factor",
    "MIN_SHARE",
    "ON_BOUND",
    "REST_MISS",
    "assign_roles",
    "family",
    "family_shares",
    "fit_warnings",
    "noise_sentence",
    "noise_summary",
    "remaining",
    "remaining_sentence",
    "record_warnings",
    "rest_warnings",
]
