"""A small two-pad model and its virtual sessions for the region-scan tests.

The two-pad geometry of ``docs/models/extension_dic_twopad.toml`` made small: a 50 x 36 mm
patch, 8 mm pads 20 mm apart, a uniform mesh of 6 elements between the pads and 2 across each pad
(5,655 unknowns), one element layer per tissue layer; the moving pad pulled along x by one
period of the Table 12 in-plane 0° sinusoid (1.5 mm peak), tracked points every 1 mm within
8 mm of the midpoint between the pads (the lab's grid). Free: both layers' Young's moduli and the
force sensor's offset along each axis (the lab's tare offsets are real offsets: left out, the
one along z is a gap that a stiff region beside the moving pad, pressing on it, partly
explains). The scar: an ``inclusion`` of the skin three times as stiff, 3 mm in radius, centred
at (3.5, −2.5) mm — away from the origin, where the declared null position would hold it, and on
no node of the scan's default grid.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

#: the truth's scar [m] and its stiffness ratio
SCAR = {"x": 3.5e-3, "y": -2.5e-3, "radius": 3e-3, "ratio": 3.0}
FREE = ["skin.E", "subdermal.E", "offset.x", "offset.y", "offset.z"]


def twopad_spec() -> dict[str, Any]:
    """The model description (no effect)."""
    from skinkit.bench.coverage import _read, _session
    from skinkit.fem.discretisation import pin_mesh

    base = _read("extension_dic_twopad.toml")
    base["geometry"].update(size=["50 mm", "36 mm"], gap="20 mm")
    spec = pin_mesh(base, [1, 1], n_pad=2, n_gap=6, n_outer=2, n_side=2, grading=1.0)
    spec.pop("load", None)
    spec["drive"] = {"max_step": "1 s"}
    # the lab tares each force component on 100 samples at rest: offsets of a tenth of the noise,
    # thousands of noise units of χ² over a record, which the model fits rather than a scar explains
    spec["instrument"] = list(spec.get("instrument", [])) + [
        {"kind": "bias", "parameter": f"offset.{c}", "value": 0.0, "channel": "tip_force", "component": i,
         "basis": "constant"} for i, c in ((1, "y"), (2, "z"))]
    return _session(spec, ["in_plane_000"], {"periods": 1})


def with_scar(spec: dict[str, Any]) -> dict[str, Any]:
    """``spec`` with the truth's scar."""
    out = copy.deepcopy(spec)
    out["effects"] = [{"name": "inclusion", **SCAR}]
    return out


def make(folder: Path, truth: dict[str, Any], seed: int, mesh: str = "own") -> Path:
    """A session file made by ``truth`` in ``folder`` (its truth file beside it)."""
    from skinkit.lab.session import make_session

    folder.mkdir(parents=True, exist_ok=True)
    make_session(truth, folder / "s.h5", folder / "truth.json", seed=seed, workers=1, mesh=mesh)
    return folder / "s.h5"
