"""Homogeneous (material-point) solutions of uniaxial and equibiaxial stretch.

The reference the finite-element solution is verified against: for a prescribed stretch
λ along x (and y, equibiaxial) the free principal stretches are found from the law's own
stress by solving ``S_yy = S_zz = 0`` (uniaxial) or ``S_zz = 0`` (equibiaxial) to machine
precision. For orthotropic laws with axes x, y, z (GOH with fibre families symmetric
about x) the deformation stays diagonal, so this is the exact solution of the boundary
value problem on a block with symmetry rollers.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.optimize import root

from skinkit.fem import lawkit
from skinkit.fem.errors import SolverError


def _S(law: Any, p: Mapping[str, Any], stretches: np.ndarray) -> np.ndarray:
    C = np.diag(np.asarray(stretches, dtype=float) ** 2)[None]
    return lawkit.stress(law, C, p)[0]


def homogeneous_stretch(law: Any, p: Mapping[str, Any], stretch: float, mode: str = "uniaxial"
                        ) -> dict[str, Any]:
    """Principal stretches and nominal stress ``P_xx = λ S_xx`` [Pa] of a homogeneous test.

    ``mode``: ``"uniaxial"`` (x loaded, y and z free) or ``"equibiaxial"`` (x and y loaded).
    Returns ``{"stretches": (3,), "P": (3, 3) nominal stress, "S": (3, 3)}``.
    """
    lam = float(stretch)
    if mode == "uniaxial":
        def f(x):
            S = _S(law, p, np.array([lam, x[0], x[1]]))
            return [S[1, 1], S[2, 2]]
        x0 = [lam ** -0.5, lam ** -0.5]
        sol = root(f, x0, method="hybr", options={"xtol": 1e-14})
        st = np.array([lam, *sol.x])
    elif mode == "equibiaxial":
        def f(x):
            return [_S(law, p, np.array([lam, lam, x[0]]))[2, 2]]
        sol = root(f, [lam ** -2], method="hybr", options={"xtol": 1e-14})
        st = np.array([lam, lam, sol.x[0]])
    else:
        raise ValueError(f"mode must be 'uniaxial' or 'equibiaxial', got {mode!r}")
    S = _S(law, p, st)
    # hybr may stop at its xtol with the residual already at rounding: judge the residual
    resid = float(np.max(np.abs(f(sol.x))))
    if not np.isfinite(resid) or resid > 1e-10 * max(abs(S[0, 0]), 1e-300):
        raise SolverError(f"homogeneous {mode} solution at stretch {lam} failed: {sol.message}")
    return {"stretches": st, "S": S, "P": np.diag(st) @ S}
