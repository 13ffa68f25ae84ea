"""Which protocols and channels see each candidate effect, and whether its null is exact.

For a model and a protocol set, every installed effect that applies to the model is added
(1) at its null value — the predictions must be those of the model without it, to rounding
— and (2) at its typical magnitude; the change of every channel, in units of that channel's
noise (one sample's standard deviation), says where the effect shows. An effect that moves
no channel by more than ``threshold`` noise levels is one the protocol set cannot see.

Progress: each prediction is an equal share of the whole
(:func:`skinkit.forward.stages.report`), its own solves advancing within its share.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from skinkit import registry
from skinkit.errors import EffectError, ForwardError
from skinkit.forward import stages
from skinkit.schemas import Observations

#: per-sample noise [SI] used when no session gives it: the robot's tip position
#: (potentiometers, 10 µm peak to peak, σ ≈ 1.7 µm), its force (Nano17 resolution 5.8 mN,
#: σ = 5.8/√12 ≈ 1.7 mN) and the stereo tracks (~7 µm RMS in 3D, ≈ 4 µm per axis)
DEFAULT_NOISE = {"tip_position": 1.7e-6, "tip_force": 1.7e-3, "points": 4e-6, "points_2d": 4e-6}


def applicable_effects(kind: str) -> list[str]:
    """Installed effects that apply to models of ``kind``."""
    out = []
    for name in registry.names("skinkit.effects"):
        try:
            plugin = registry.create("skinkit.effects", name)
        except Exception:  # a broken plugin is listed by `skinkit plugins`, not here
            continue
        if kind in tuple(getattr(plugin, "kinds", ())):
            out.append(name)
    return out


def _max_change(a, b, obs: Observations, noise: Mapping[str, float] | None) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for (proto, c, x), (_, _, y) in zip(a.items(), b.items(), strict=True):
        ch = obs[proto].channels[c]
        m = x.mask(ch)
        sig = ch.noise if noise is None else np.full(ch.noise.shape, noise.get(c, 1.0))
        diff = np.where(m, np.abs(x.values - y.values) / sig, 0.0)
        out.setdefault(proto, {})[c] = float(diff.max()) if diff.size else 0.0
    return out


def _rel_change(a, b) -> float:
    worst = 0.0
    for (_, _, x), (_, _, y) in zip(a.items(), b.items(), strict=True):
        scale = float(np.max(np.abs(y.values))) if y.values.size else 0.0
        if scale > 0:
            worst = max(worst, float(np.max(np.abs(x.values - y.values))) / scale)
    return worst


def effect_visibility(spec: Mapping[str, Any], observations: Observations,
                      effects: Sequence[str] | None = None, noise: Mapping[str, float] | None = None,
                      threshold: float = 5.0,
                      load: Callable[..., Any] | None = None,
                      progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """For each effect: the null's largest relative change, and per protocol and channel the
    largest change at the typical magnitude in noise levels (``noise``: channel -> σ [SI];
    None: each channel's own noise). JSON-ready."""
    from skinkit.forward import load as default_load
    from skinkit.forward import model_kind

    load = load or default_load
    base_spec = copy.deepcopy(dict(spec))
    base_spec.pop("effects", None)
    kind = model_kind(base_spec)
    names = list(effects) if effects is not None else applicable_effects(kind)
    runs = [0, 1 + 2 * len(names)]   # predictions made, and at most to make (for the progress)

    def predicted(model: Any, note: str) -> Any:
        stages.report(runs[0] / runs[1], note)
        with stages.portion(runs[0] / runs[1], (runs[0] + 1) / runs[1], note):
            pred = model.predict(model.parameters(), observations)
        runs[0] += 1
        return pred

    with load(base_spec) as base:
        ref = predicted(base, "the model without effects")
    out: dict[str, Any] = {"threshold": threshold, "protocols": observations.names, "effects": {}}
    for name in names:
        if progress is not None:
            progress(name)
        plugin = registry.create("skinkit.effects", name)
        with_null = copy.deepcopy(base_spec)
        with_null["effects"] = [{"name": name}]
        try:
            with load(with_null) as m0:
                null_change = _rel_change(predicted(m0, f"{name} at its null"), ref)
        except (EffectError, ForwardError) as exc:   # e.g. `fibres` on a skin with a fibre law already
            out["effects"][name] = {"applicable": False, "reason": str(exc), "visible": False}
            runs[1] -= 2     # neither of its predictions is made
            continue
        typical = {p.name: p.value for p in plugin.parameters()}
        with_typ = copy.deepcopy(base_spec)
        with_typ["effects"] = [{"name": name, **typical}]
        with load(with_typ) as m1:
            change = _max_change(predicted(m1, f"{name} at its typical magnitude"), ref, observations, noise)
        seen = {p: [c for c, v in chans.items() if v > threshold] for p, chans in change.items()}
        out["effects"][name] = {"applicable": True, "typical": typical, "null_relative_change": null_change,
                                "change_in_noise": change,
                                "seen_by": {p: cs for p, cs in seen.items() if cs},
                                "visible": any(seen.values())}
    stages.report(1.0, "done")
    out["invisible"] = [n for n, e in out["effects"].items() if e["applicable"] and not e["visible"]]
    out["not_applicable"] = {n: e["reason"] for n, e in out["effects"].items() if not e["applicable"]}
    return out


__all__ = ["DEFAULT_NOISE", "applicable_effects", "effect_visibility"]
