"""The example models meet 5 % on the tip quantity at their documented loads.

Each finite-element example in ``docs/models`` is solved at its documented load (one static
ramp to the programme's peak: the sinusoid's peak depth or force, the ramp's end) on meshes
of its own family (every count scaled by the factors below, gradings and layout kept;
factors below 1 coarsen the file's mesh), and the discretisation error of the file's mesh is
the Richardson estimate over those levels (:func:`skinkit.fem.discretisation.richardson`):
the order observed over the three finest levels, or, with two levels, the lowest order a
bonded probe's edge gives (1), so that estimate errs large. Nothing here is copied from a run:
the assertion is the estimate against the 5 % the issue asks for.

The membrane phantom is cheap (two levels, about 3 s) and runs in the suite. The others need
levels of 50,000 to 200,000 unknowns (one to twenty minutes each on two cores): they run
when ``SKINKIT_EXAMPLE_STUDIES=1`` is set —

    SKINKIT_EXAMPLE_STUDIES=1 SKINKIT_MAX_UNKNOWNS=200000 \\
        .venv/bin/python -m pytest tests/fem/test_examples_converged.py -q -s

— and print each level; docs/reference/model-files.md lists what they gave. Every example's study
factors are checked in the suite to scale its file's counts to whole numbers, so the
documented study stays runnable.
"""

from __future__ import annotations

import os
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from skinkit.fem.discretisation import ASSUMED_ORDER, refined_spec, richardson
from skinkit.fem.model import build_model, estimate_size, layer_table, read_model
from skinkit.fem.run import solve_model

pytestmark = pytest.mark.needs_plugins

MODELS = Path(__file__).resolve().parents[2] / "docs" / "models"
#: the error the issue allows on the tip force (tip motion under force control)
TOLERANCE = 0.05

#: per example: the documented load as one static ramp (None: the file's own ramp), and the
#: refinement factors of its study (the file's mesh is factor 1)
STUDIES = {
    "phantom_membrane_gel": (None, ["1", "2"]),
    "invivo_quick": ({"kind": "ramp", "value": ["0 N", "0 N", "-20 mN"], "steps": 2},
                     ["1/2", "1", "3/2", "2"]),
    "invivo_static_force": (None, ["1/2", "1", "3/2", "2"]),
    "invivo_goh_qlv": ({"kind": "ramp", "value": ["0 mm", "0 mm", "-1.5 mm"], "steps": 3},
                       ["1/3", "2/3", "1"]),
    "phantom_cube_box": (None, ["1/3", "2/3", "1"]),
    # the file's mesh is the coarsest of the three finest levels (2/3 is a cheap extra): the
    # order is observed from finer levels than the file's, not from pre-asymptotic coarse ones;
    # 5/3 (197,253 unknowns) stays within the SKINKIT_MAX_UNKNOWNS the docstring gives
    "extension_dic_twopad": (None, ["2/3", "1", "4/3", "5/3"]),
}
CHEAP = {"phantom_membrane_gel"}
FULL = os.environ.get("SKINKIT_EXAMPLE_STUDIES") == "1"


def _static(name: str) -> dict:
    """The example at its documented load: a static ramp, no session tables, no sensitivities."""
    spec = read_model(MODELS / f"{name}.toml")
    load, _ = STUDIES[name]
    if load is not None:
        spec["load"] = dict(load)
    elif spec["load"].get("kind") == "ramp":
        spec["load"] = dict(spec["load"], steps=min(int(spec["load"]["steps"]), 4))
    for key in ("session", "surface", "drive"):
        spec.pop(key, None)
    if isinstance(spec.get("output"), dict):
        spec["output"] = dict(spec["output"], sensitivities=False)
    return spec


def _study(name: str) -> tuple[float, dict]:
    """The estimated relative error of the file's mesh and the study's figures."""
    spec = _static(name)
    factors = [Fraction(f) for f in STUDIES[name][1]]
    key = "tip_displacement_m" if spec.get("indenter", {}).get("mode") == "force" else "tip_force_N"
    values, dofs = [], []
    for f in factors:
        _, info = solve_model(build_model(refined_spec(spec, f)))
        values.append(np.array(info["steps"][-1][key], dtype=float))
        dofs.append(info["dof"])
        print(f"{name} {f}x: {info['dof']:,} unknowns, {key} {values[-1].tolist()}, {info['wall_s']:.1f} s")
    est = richardson(values, [float(f) for f in factors], ASSUMED_ORDER if len(values) < 3 else None)
    i = factors.index(Fraction(1))
    rel = float(np.linalg.norm(est["errors"][i]) / np.linalg.norm(est["extrapolated"]))
    print(f"{name}: observed order {est['observed_order']:.3g}, monotone {est['monotone']}, "
          f"extrapolated {np.asarray(est['extrapolated']).tolist()}, file's mesh {rel:.2%}")
    return rel, {"dof": dofs, "order": est["order"], "monotone": est["monotone"]}


@pytest.mark.parametrize("name", sorted(STUDIES))
def test_study_factors_scale_the_files_counts(name):
    # the documented study stays runnable: every factor gives whole counts, and the sizes
    # grow with the factor (checked from the counts, nothing is built beyond the file's mesh)
    spec = _static(name)
    sizes = [estimate_size(r, layer_table(r))["unknowns"]
             for r in (refined_spec(spec, Fraction(f)) for f in STUDIES[name][1])]
    assert sizes == sorted(sizes) and len(set(sizes)) == len(sizes)


@pytest.mark.parametrize("name", sorted(STUDIES))
def test_example_meets_five_percent_at_its_documented_load(name):
    if name not in CHEAP and not FULL:
        pytest.skip("a study of several minutes: set SKINKIT_EXAMPLE_STUDIES=1 "
                    "(docs/reference/model-files.md)")
    rel, info = _study(name)
    assert rel < TOLERANCE, (name, rel, info)
