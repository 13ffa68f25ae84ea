"""The final model refitted with its discretisation error estimated where it is."""

from __future__ import annotations

from skinkit.bench.coverage import lumped_spec
from skinkit.forward import load
from skinkit.gap.final_model import refit_final
from skinkit.inverse import fit
from skinkit.inverse.coverage import LabSessions


def test_a_model_without_a_mesh_keeps_its_own_final_fit():
    """The re-estimate needs a refinable mesh: for a lumped model it is refused, said, recorded as
    a warning for the report, and the diagnosis's own final fit stands (None)."""
    spec, free = lumped_spec()
    lab = LabSessions(spec)
    obs = lab(0)
    model = load(lab.model_spec)
    try:
        result = fit(model, obs, free, start={n: float(model.parameters()[n]) for n in free})
    finally:
        model.close()
    said: list[str] = []
    warnings: list[dict] = []
    assert refit_final(lab.model_spec, obs, result, free, load, said.append, 5, warnings) is None
    assert "not refitted with its own discretisation error" in said[-1]
    assert "no mesh" in said[-1]
    got = [(w["kind"], w["where"], w["message"]) for w in warnings]
    assert got == [("refit-failed", "final model", said[-1])]
