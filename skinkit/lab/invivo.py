"""A layered in vivo finite-element model of the forearm test site (thesis 7.4–7.5).

The 40 mm test region with a 4 mm indenter: 1.5 mm of skin (nearly incompressible
neo-Hookean, μ = 15 kPa) over 3.5 mm of subdermal tissue (E = 10 kPa, ν = 0.45), outer ring
and floor fixed, the indenter driven by a measured-style tip force. The skin's natural
tension, which the thesis could not model (reference lines 8330–8420), is an in-plane
pre-stretch of 10 % along the Langer line (20° from x) and 3 % across.
"""

from __future__ import annotations

import copy
from typing import Any

_SPEC: dict[str, Any] = {
    "model": {"name": "invivo-static-force"},
    "geometry": {"kind": "disc", "diameter": "40 mm", "indenter_diameter": "4 mm",
                 "n_inner": 2, "n_ring": 3},
    "layers": [
        {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "neo-hookean-ni",
         "parameters": {"mu": "15 kPa", "K": "500 kPa"},
         "prestress": {"stretch": [1.10, 1.03], "angle": "20 deg"}},
        {"name": "subdermal", "thickness": "3.5 mm", "elements": 2, "law": "neo-hookean-enu",
         "parameters": {"E": "10 kPa", "nu": 0.45}},
    ],
    "boundary": {"fixed": ["outer", "bottom"]},
    "indenter": {"mode": "force"},
    "load": {"kind": "ramp", "value": ["0 N", "0 N", "-20 mN"], "steps": 4},
}

#: the laws the model needs (plugins of the ``skinkit.laws`` group)
LAWS = ("neo-hookean-ni", "neo-hookean-enu")


def static_force_spec(prestretch: bool = True, force_N: float = 0.02) -> dict[str, Any]:
    """The model as a mapping in the TOML model format (``docs/reference/model-files.md``): normal
    tip force ``force_N`` [N] into the skin; ``prestretch`` False drops the natural tension."""
    spec = copy.deepcopy(_SPEC)
    spec["load"]["value"] = ["0 N", "0 N", f"{-force_N} N"]
    if not prestretch:
        del spec["layers"][0]["prestress"]
        spec["model"]["name"] = "invivo-static-force-no-prestress"
    return spec
