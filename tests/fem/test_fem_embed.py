"""Surface fitting and embedded material points."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit import registry
from skinkit.fem.bcs import BoundaryConditions
from skinkit.fem.embed import embed_points, fit_surface
from skinkit.fem.errors import ModelError
from skinkit.fem.mesh import block_mesh, disc_mesh
from skinkit.fem.problem import Material, Problem
from skinkit.fem.sensitivity import sensitivities
from skinkit.fem.solver import NewtonSolver


def _surface(x, y):
    """A gentle dome: 0.3 mm high at the centre, zero at the 20 mm rim."""
    r2 = (x ** 2 + y ** 2) / 0.02 ** 2
    return 3e-4 * np.clip(1 - r2, 0, None)


def test_fit_surface_keeps_skin_thickness_and_reports_rms():
    m = disc_mesh()
    rng = np.random.default_rng(3)
    xy = rng.uniform(-0.019, 0.019, size=(3000, 2))
    xy = xy[np.hypot(*xy.T) < 0.019]
    pts = np.column_stack([xy, _surface(*xy.T)])
    fit = fit_surface(m, pts, skin_thickness=0.0015, keep=("outer",))
    top = m.node_sets["top"]
    # nodes sit on the measured surface up to linear interpolation between 3000 scattered
    # points (spacing ~0.6 mm, |z''| = 2 * 3e-4 / 0.02² = 1.5 /m: h² |z''| / 8 ≈ 0.07 µm)
    np.testing.assert_allclose(fit.mesh.nodes[top, 2], _surface(*m.nodes[top, :2].T), atol=1e-6)
    # the RMS is against the surface interpolated between top nodes, up to ~4.3 mm apart in
    # the outer ring (diagonals ~6 mm): (6e-3)² * 1.5 / 8 ≈ 7 µm at worst
    assert fit.rms < 1e-5 and fit.max_abs < 1e-5
    # skin thickness kept: nodes 1.5 mm below the top moved by the same dz as the top
    dz = fit.mesh.nodes[:, 2] - m.nodes[:, 2]
    below = np.flatnonzero(np.isclose(m.nodes[:, 2], -0.0015))
    for n in below[:20]:
        col = top[np.argmin(np.linalg.norm(m.nodes[top, :2] - m.nodes[n, :2], axis=1))]
        assert np.isclose(dz[n], dz[col], atol=1e-12)
    assert np.allclose(dz[m.node_sets["bottom"]], 0) and np.allclose(dz[m.node_sets["outer"]], 0)


def test_embedding_recovers_points_and_follows_deformation():
    m = disc_mesh(n_inner=2, n_ring=2)
    rng = np.random.default_rng(5)
    ang = rng.uniform(0, 2 * np.pi, 40)
    r = rng.uniform(0, 0.015, 40)
    pts = np.column_stack([r * np.cos(ang), r * np.sin(ang), np.zeros(40)])
    emb = embed_points(m, pts, depth=2e-4)
    # inverse then forward isoparametric map: Newton converged to 1e-10 in local coordinates
    np.testing.assert_allclose(emb.positions(m.nodes), pts - [0, 0, 2e-4], atol=1e-11)
    # a homogeneous displacement field is reproduced exactly at embedded points
    A = np.array([[0.01, 0.02, 0], [0, -0.01, 0], [0.005, 0, 0.02]])
    u = m.nodes @ A.T
    expect = (pts - [0, 0, 2e-4]) @ (np.eye(3) + A).T
    np.testing.assert_allclose(emb.positions(m.nodes, u), expect, atol=1e-11)
    with pytest.raises(ModelError, match="outside the mesh"):
        embed_points(m, np.array([[0.05, 0.0, 0.0]]))


@pytest.mark.needs_plugins
def test_embedded_point_sensitivities_via_position_jacobian():
    L = 0.01
    m = block_mesh((L, L, L), (2, 2, 2))
    law = registry.create("skinkit.laws", "neo-hookean-ni")
    prob = Problem(m, [Material("body", law, {"mu": 1e4, "K": 1e5})])
    s = m.node_sets
    bc = BoundaryConditions(m.n_dof).fix(s["bottom"]).prescribe(s["top"], 0, lambda t: 1e-3 * t)
    solver = NewtonSolver(prob, bc)
    sol = solver.run([1.0])
    emb = embed_points(m, np.array([[0.003, 0.004, -0.002], [0.007, 0.005, -0.006]]))
    sens = sensitivities(solver, sol.u[-1], 1.0)
    dP = emb.position_jacobian(m.n_dof) @ sens.du
    # prescribed displacements only: positions do not depend on the moduli's common scale,
    # and the exact identity mu dP/dmu + K dP/dK = 0 (homogeneity of degree 0) holds
    comb = 1e4 * dP[:, 0] + 1e5 * dP[:, 1]
    moved = np.abs(emb.positions(m.nodes, sol.u[-1]) - emb.positions(m.nodes)).max()
    assert np.abs(comb).max() <= 1e-9 * moved


def test_point_on_a_face_that_bulges_above_its_nodes_is_found():
    """A quadratic top face whose node heights along x are (0, 0, -d) rises to d/8 above its
    highest node at a quarter of the edge (a profile-fitted face beside flat nodes under an
    indenter does this, by micrometres); a point there lies in the element and must be found.

    Regression: the candidate boxes were padded by 1e-3 of the element's size only, so a point
    on such a bulge (here d/8 = 2.5 % of the size) was reported outside the mesh."""
    from skinkit.fem.embed import _shape

    m = block_mesh((1e-3, 1e-3, 1e-3), (1, 1, 1))
    x, z = m.nodes[:, 0], m.nodes[:, 2]
    top = np.isclose(z, 0.0)
    d = 0.2e-3
    m.nodes[top & np.isclose(x, 1e-3), 2] = -d       # the far edge of the top face lowered by d
    # the highest point of the element's faces: d/8 above every node's height
    Xe = m.nodes[m.elements[0]]
    s = np.linspace(0.0, 1.0, 41)
    a, b = (g.ravel() for g in np.meshgrid(s, s))
    faces = [np.insert(np.vstack([a, b]), k, end, axis=0) for k in range(3) for end in (0.0, 1.0)]
    P = np.vstack([_shape(xi)[0].T @ Xe for xi in faces])
    p = P[np.argmax(P[:, 2])]
    assert p[2] == pytest.approx(d / 8, rel=1e-9)     # the construction does bulge, by d/8
    emb = embed_points(m, p[None])
    assert np.allclose(emb.positions(m.nodes)[0], p, rtol=0, atol=1e-12)


def test_tensor_product_shapes_are_scikit_fems_hex27_basis():
    """The embedding's shape functions, built as products of 1D quadratics, are scikit-fem's
    ElementHex2 basis (value and gradient) to rounding, inside the element and beyond it."""
    from skfem import ElementHex2

    from skinkit.fem.embed import _shape

    xi = np.random.default_rng(0).uniform(-0.5, 1.5, (3, 200))
    N, dN = _shape(xi)
    for a in range(27):
        n, dn = ElementHex2().lbasis(xi, a)
        assert np.abs(N[a] - n).max() < 1e-13 and np.abs(dN[a] - dn).max() < 1e-12
    assert np.allclose(N.sum(axis=0), 1.0, atol=1e-13)
