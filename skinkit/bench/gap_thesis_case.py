"""The thesis's case of the gap diagnosis: the skin's natural pre-stress withheld.

A virtual in vivo session whose truth is the coarse layered forearm model
(``docs/models/invivo_quick.toml`` as the coverage study coarsens it: one inner element ring, one
0.1 Hz period per protocol, displacement-driven Table 12 programmes — normal indentation, in-plane
0° and 90°, out-of-plane 330°) **with** the skin's natural pre-stress along a Langer line
(``prestress``: λ1 = 1.10, λ2 = 1.03, 20° from x), Gaussian noise at the lab's declared levels
(:class:`skinkit.inverse.coverage.LabSessions`), is diagnosed with the thesis's model — GOH + QLV
skin **without** pre-stress, c, k1, κ and g1 free (thesis 7.6). Reported: where the gap lies,
the score ranking, what is named, the shrinkage, and the named effect's parameters against the
truth. A pre-stretch (λ1, λ2, θ) equals (λ2, λ1, θ ± 90°); estimates are put in the truth's
convention (λ1 ≥ λ2, θ in (−90°, 90°]) before they are compared.
"""

from __future__ import annotations

import copy
import math
import time
from typing import Any

from skinkit.lab.forearm import canonical_prestress

TRUTH = {"name": "prestress", "l1": 1.10, "l2": 1.03, "angle": math.radians(20.0)}


def run(seed: int = 0, workers: int | None = 2, progress: Any = None) -> dict[str, Any]:
    """Make the session, diagnose it; JSON-ready figures (the report under ``"report"``)."""
    from skinkit.bench.coverage import invivo_spec
    from skinkit.gap import diagnose
    from skinkit.inverse.coverage import LabSessions

    t0 = time.perf_counter()
    spec, free = invivo_spec()
    truth = copy.deepcopy(spec)
    truth["effects"] = [dict(TRUTH)]
    lab = LabSessions(truth, workers=workers, mesh="shared")
    obs = lab(seed)
    model = copy.deepcopy(lab.model_spec)
    model.pop("effects", None)
    # the truth shares the model's mesh here: no model error to carry
    report = diagnose(model, obs, free=free, workers=workers, max_effects=1, progress=progress,
                      model_error=False).to_dict()
    out: dict[str, Any] = {"seed": seed, "truth": {k: v for k, v in TRUTH.items() if k != "name"},
                           "protocols": lab.protocols, "named": report["named"],
                           "wall_s": time.perf_counter() - t0}
    cells = [c for c in report["gap"]["cells"] if c["axis"] == "protocol"]
    out["protocol_shares"] = {c["label"]: c["share"] for c in cells}
    out["protocol_chi2_per_dof"] = {c["label"]: c["chi2_per_dof"] for c in cells}
    named = next((c for c in report["candidates"] if c["effect"] == "prestress" and c["parameters"]), None)
    if named is not None:
        p = {k.split(".", 1)[1]: v["value"] for k, v in named["parameters"].items()}
        l1, l2, a = canonical_prestress(p["l1"], p["l2"], p["angle"])
        out["prestress"] = {"l1": l1, "l2": l2, "angle": a}
        out["prestress_error"] = {"l1": l1 - TRUTH["l1"], "l2": l2 - TRUTH["l2"],
                                  "angle_deg": math.degrees(a - TRUTH["angle"])}
    out["shrinkage"] = report["shrinkage"]["overall"]
    out["ranking"] = [(c["effect"], c["score"]) for c in report["candidates"]]
    out["report"] = report
    return out
