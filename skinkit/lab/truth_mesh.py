"""The virtual lab's finite-element truth on a mesh of its own.

A truth solved on the mesh of the model under test, by the same code, carries none of the model's
discretisation error: the inverse crime (Kaipio & Somersalo, J Comput Appl Math 198, 2007). The
skin is an infinitely fine truth; the lab's stands in for it with a mesh the model does not share:

* every in-plane element count multiplied by ``factor`` (default 2) and every layer's element
  layers by ``factor + 1`` (about 10x the unknowns of 27-node hexahedra), and
* its own node placement: the radial grading towards the indenter, the grading towards the
  indenter's edge inside it, the grading through the thickness and the pads' grading each moved
  (:data:`GRADINGS`), so that no node of the model's mesh, nor of the model's own refinement
  check (:mod:`skinkit.inverse.approximation`, uniform 2x), lies where the truth's do.

The truth's own discretisation error is estimated from the same truth solved on the model's mesh
(:func:`error_figures`): with a convergence order ≥ 1 and a factor f, the finer solution's error is
at most |fine − coarse| / (f − 1); the truth file states it per channel against the noise.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError

#: how the truth meshes: on its own mesh (default), on three of its own extrapolated to a vanishing
#: element size ("extrapolated", :mod:`skinkit.lab.truth_extrapolation`), or on the model's
#: ("shared": the inverse crime, kept for comparison)
MESH_MODES = ("own", "extrapolated", "shared")
#: default refinement of the truth's mesh over the model's
DEFAULT_FACTOR = 2
#: geometry key -> the truth's grading as a function of the model's (every grading >= 1)
GRADINGS = {
    "grading": lambda g: 1.0 + 1.4 * (g - 1.0) if g > 1.0 else 1.3,
    "inner_grading": lambda g: g + 0.3,
    "layer_grading": lambda g: g + 0.3,
    "pad_grading": lambda g: g + 0.3,
}


class TruthMeshError(SkinkitError):
    """A truth mesh option that cannot be used."""


def check_mode(mode: str, factor: int) -> None:
    """``mode`` one of :data:`MESH_MODES`, ``factor`` a whole number >= 2 (>= 3 extrapolated)."""
    if mode not in MESH_MODES:
        raise TruthMeshError(f"truth mesh: expected one of {', '.join(MESH_MODES)}, got {mode!r}")
    least = 3 if mode == "extrapolated" else 2
    if isinstance(factor, bool) or not isinstance(factor, int) or factor < least:
        raise TruthMeshError(f"truth mesh factor: expected a whole number >= {least}"
                             + (" (three members 1..3 times the model's counts)" if least == 3 else "")
                             + f", got {factor!r}")


def own_gradings(spec: Mapping[str, Any], factor: int) -> dict[str, Any]:
    """A deep copy of ``spec`` with every element count (in-plane and each layer's) times
    ``factor`` and every grading moved as the truth's own mesh moves it (:data:`GRADINGS`)."""
    from skinkit.fem.discretisation import MESH_KEYS, refined_spec

    s = refined_spec(spec, factor)
    g = s["geometry"]
    kind = g.get("kind", "disc")
    if kind == "block" and g.get("fit_indenter") is True:
        kind = "block_fitted"
    defaults = MESH_KEYS.get(kind, {})
    for key, move in GRADINGS.items():
        if key in defaults:
            g[key] = float(move(float(g.get(key, defaults[key]))))
    return s


def own_mesh(spec: Mapping[str, Any], factor: int = DEFAULT_FACTOR) -> dict[str, Any]:
    """A deep copy of the finite-element description ``spec`` on the truth's own mesh (module)."""
    from skinkit.fem.discretisation import LAYER_ELEMENTS_DEFAULT

    check_mode("own", factor)
    s = own_gradings(spec, factor)
    # one more element layer per factor through the thickness: the skin's gradients under the
    # indenter run across its thin layers, and the truth then has >= 8x the model's unknowns
    for L, L0 in zip(s["layers"], spec["layers"], strict=True):
        L["elements"] = int(L0.get("elements", LAYER_ELEMENTS_DEFAULT)) * (factor + 1)
    return s


def mesh_figures(spec: Mapping[str, Any]) -> dict[str, int]:
    """``elements`` and ``unknowns`` of a finite-element description's mesh (counted, not built)."""
    from skinkit.fem.model import estimate_size, layer_table

    size = estimate_size(spec, layer_table(spec))
    return {"elements": int(size["elements"]), "unknowns": int(size["unknowns"])}


def describe_meshes(truth: Mapping[str, Any], model: Mapping[str, Any], mode: str,
                    factor: int) -> dict[str, Any]:
    """The truth file's ``mesh`` entry: the mode, the factor and both meshes' figures."""
    t, m = mesh_figures(truth), mesh_figures(model)
    return {"mode": mode, "factor": factor if mode != "shared" else 1,
            "truth_elements": t["elements"], "truth_unknowns": t["unknowns"],
            "model_elements": m["elements"], "model_unknowns": m["unknowns"],
            "gradings": {k: v for k, v in dict(truth.get("geometry", {})).items() if k.endswith("grading")}}


def largest_truth_error(mesh: Mapping[str, Any]) -> float | None:
    """The largest ``truth_over_noise`` over the channels of a truth file's ``mesh`` entry (the
    bound on the truth's own error, in noise levels), or None when it has no such figure."""
    rows = (mesh.get("discretisation") or {}).values()
    vals = [float(r["truth_over_noise"]) for r in rows if r and r.get("truth_over_noise") is not None]
    return max(vals) if vals else None


def error_figures(fine: Mapping[str, Mapping[str, np.ndarray]],
                  coarse: Mapping[str, Mapping[str, np.ndarray]], noise: Mapping[str, float],
                  factor: int) -> dict[str, dict[str, float | None]]:
    """Per channel (over protocols; tracked points by their motion since the first frame): RMS of
    the truth's estimated discretisation error, ``|fine − coarse| / (factor − 1)`` [unit] (an
    upper bound at order ≥ 1), the model mesh's (``|fine − coarse|`` · f/(f − 1): the same truth
    on the model's mesh) and each over the noise level ``noise[channel]`` [unit]."""
    acc: dict[str, list[np.ndarray]] = {}
    for proto, chans in fine.items():
        for c, v in chans.items():
            w = coarse.get(proto, {}).get(c)
            if w is None or np.shape(w) != np.shape(v):
                continue
            v, w = np.asarray(v, float), np.asarray(w, float)
            if v.ndim == 3 and v.shape[1] > 1:
                # tracked points by their motion since the first frame, as a session refers them:
                # each mesh embeds them on its own approximation of a curved top (a static offset)
                v, w = v - v[:, :1], w - w[:, :1]
            d = v - w
            acc.setdefault(c, []).append(d[np.isfinite(d)].ravel())
    out = {}
    for c, parts in acc.items():
        d = np.concatenate(parts)
        if not d.size or not np.any(d):
            continue     # a drive channel: the same on both meshes
        rms = float(np.sqrt(np.mean(d ** 2)))
        truth_rms, model_rms = rms / (factor - 1), rms * factor / (factor - 1)
        sig = noise.get(c)
        out[c] = {"truth_rms": truth_rms, "model_rms": model_rms, "noise": sig,
                  "truth_over_noise": truth_rms / sig if sig else None,
                  "model_over_noise": model_rms / sig if sig else None}
    return out


__all__ = ["DEFAULT_FACTOR", "GRADINGS", "MESH_MODES", "TruthMeshError", "check_mode",
           "describe_meshes", "error_figures", "largest_truth_error", "mesh_figures", "own_gradings",
           "own_mesh"]
