"""A truth the model cannot share: the virtual lab solves a small disc on a mesh of its own (2x
finer in-plane, 3x through the thickness, its own gradings), with no effect at all; the model is the
same disc on its coarse mesh. The coarse mesh is too stiff, so the calibrated model leaves a
residual far above the noise that softening candidates (a compliant support, an inclusion) would
take. The diagnosis estimates the mesh's error at the calibration, carries it as noise, and names
nothing; its report states the error per channel against the noise, the share of the residual
it accounts for and, the mesh being the largest term, which refinement would bring it below the
noise."""

from __future__ import annotations

import copy

import pytest

pytestmark = pytest.mark.needs_plugins


def test_a_mesh_gap_alone_is_attributed_to_the_mesh_and_nothing_is_named():
    from skinkit.bench.mesh_nulls import CASES
    from skinkit.gap.diagnose import diagnose
    from skinkit.inverse.coverage import LabSessions

    spec, _ = CASES["disc-gel"]()
    lab = LabSessions(spec, workers=1)
    assert lab.truth.truth["mesh"]["mode"] == "own"
    rep = diagnose(copy.deepcopy(lab.model_spec), lab(0), effects=["support-compliance", "inclusion"],
                   free=["gel.E"], workers=1, max_effects=1, candidates=1)
    d = rep.to_dict()
    assert rep.named == [], d["messages"]
    err = d["model_error"]
    assert err is not None and d["discretisation"] is None       # carried, not projected
    assert err["unknowns_refined"] > 5 * err["unknowns"]
    assert all(row["rms_over_noise"] > 1 for row in err["channels"].values()), err["channels"]
    assert err["accounts_for"] is not None and err["accounts_for"] >= 0.5
    text = " ".join(d["messages"])
    assert "Model error" in text and "The mesh, not the physics, is the largest term" in text
    # the remainder the report states is the carried residual's, consistent across its cells
    rem = d["remaining"]
    for cell in rem["cells"]:
        if cell["axis"] == "protocol":
            assert cell["chi2_per_dof"] == pytest.approx(rem["chi2_per_dof"], rel=0.05)
