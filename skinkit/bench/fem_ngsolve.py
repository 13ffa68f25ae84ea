"""NGSolve as a compiled peer of ``skinkit bench fem``: the same problem in C++ assembly.

The block's own mesh (its vertices and 8-vertex hexahedra) becomes a Netgen mesh, and
NGSolve's order-2 ``VectorH1`` space on hexahedra is the 27-node hexahedron's space (the
tensor-product Q2, in a hierarchical basis whose vertex values are the nodal values). The
law is W = μ/2 (J^(-2/3) I1 - 3) + K/2 (J - 1)², the same energy as skinkit's and sfepy's,
differentiated twice by NGSolve (``Variation``) on the same 3 x 3 x 3 Gauss rule. The step is
solved as skinkit solves it: a tangent predictor at the undeformed state spreads the top
face's displacement through the body, then full Newton steps until the residual of the
free unknowns is below ``rtol`` times the predictor's right-hand side. One thread
(``ngsolve.SetNumThreads(1)``, no task manager); every tangent is factorised anew by
NGSolve's own sparse direct solver.

Importing this module does not import NGSolve: :func:`run_ngsolve` does, so that a missing
NGSolve is an ``ImportError`` naming ``ngsolve`` (or ``netgen``) when the peer runs.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

from skinkit.fem.assembly import DEFAULT_INTORDER
from skinkit.fem.output import VTK_HEX_ORDER

#: netgen's hexahedron from VTK's: the same two quadrilaterals, each walked the other way, as
#: NGSolve's own structured hexahedral meshes number them (``ngsolve.meshes``); NGSolve
#: integrates with |det J|, so either turn gives the same answer
NETGEN_FROM_VTK = np.array([0, 3, 2, 1, 4, 7, 6, 5])
#: the six faces of a netgen hexahedron (local vertex numbers)
HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
#: the direct solver: NGSolve's own sparse LDLᵀ (its UMFPACK was 1.5x slower on the 7³ block;
#: the PyPI build has no PARDISO)
INVERSE = "sparsecholesky"


def ngsolve_mesh(mesh: Any):
    """An ``ngsolve.Mesh`` of ``mesh``'s vertices [m] and linear hexahedra, boundaries
    ``bottom`` (z minimum), ``top`` (z maximum) and ``free`` (the sides)."""
    import ngsolve
    from netgen import meshing

    nv = int(mesh.t.max()) + 1
    conn = np.ascontiguousarray(mesh.t.T[:, VTK_HEX_ORDER][:, NETGEN_FROM_VTK], dtype=np.int32)
    m = meshing.Mesh(dim=3)
    m.AddPoints(np.ascontiguousarray(mesh.nodes[:nv], dtype=float))
    m.SetMaterial(1, "body")
    m.AddElements(dim=3, index=1, data=conn, base=0)
    faces = conn[:, HEX_FACES].reshape(-1, 4)
    _, first, count = np.unique(np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True)
    outer = faces[first[count == 1]]          # a face of one element only is on the boundary
    z = mesh.nodes[:nv, 2]
    zf = z[outer]
    tol = 1e-9 * float(np.ptp(z))
    bottom, top = np.all(zf < z.min() + tol, axis=1), np.all(zf > z.max() - tol, axis=1)
    for i, (name, sel) in enumerate((("bottom", bottom), ("top", top), ("free", ~(bottom | top)))):
        m.Add(meshing.FaceDescriptor(surfnr=i + 1, domin=1, domout=0, bc=i + 1))
        m.SetBCName(i, name)
        m.AddElements(dim=2, index=i + 1, data=np.ascontiguousarray(outer[sel], dtype=np.int32), base=0)
    return ngsolve.Mesh(m)


@contextlib.contextmanager
def _compiler_on_path() -> Iterator[None]:
    """NGSolve's ``realcompile`` calls ``ngscxx``, which pip installs beside the interpreter
    (the virtual environment's ``bin``), not always on ``PATH``: put it there for the block."""
    old = os.environ.get("PATH", "")
    os.environ["PATH"] = os.pathsep.join([os.path.dirname(sys.executable), old])
    try:
        yield
    finally:
        os.environ["PATH"] = old


def _energy_form(fes, mu: float, bulk: float, compiled: bool):
    """The total Lagrangian energy ∫ W dX as an NGSolve ``BilinearForm`` (its linearisation is
    the tangent); returns ``(form, how)`` with ``how`` the way its integrand was compiled."""
    import ngsolve as ng

    u = fes.TrialFunction()
    F = ng.Id(3) + ng.Grad(u)
    J = ng.Det(F)
    W = mu / 2 * (J ** (-2 / 3) * ng.Trace(F.trans * F) - 3) + bulk / 2 * (J - 1) ** 2
    how = "expression tree (Compile)"
    cf = W.Compile()
    if compiled:
        try:
            with _compiler_on_path():
                cf = W.Compile(realcompile=True, wait=True)
            how = "C++ (Compile realcompile)"
        except Exception:   # no C++ compiler: NGSolve's interpreted expression tree still runs
            pass
    form = ng.BilinearForm(fes, symmetric=True)
    rule = ng.IntegrationRule(ng.HEX, DEFAULT_INTORDER)
    form += ng.Variation(cf * ng.dx(intrules={ng.HEX: rule}))
    return form, how


def run_ngsolve(mesh: Any, mu: float, bulk: float, top_u: tuple[float, float, float],
                rtol: float = 1e-10, max_iter: int = 30, compiled: bool = True) -> dict:
    """Solve the block with NGSolve: floor fixed, top face moved by ``top_u`` [m], moduli
    ``mu``, ``bulk`` [Pa], one load step.

    Returns the displacement at the vertices ``u`` (nv, 3) [m], ``wall`` [s] of the solve
    (predictor and Newton iterations, from the first tangent to the converged residual),
    ``setup_s`` [s] (mesh, space, form and its compilation), ``factorisations``,
    ``s_per_newton``, ``tangent_assembly_s`` and ``solve_s`` [s] per factorisation,
    ``residuals`` (free-unknown residual norms relative to the reference), ``inverse`` and
    ``assembly`` (how the integrand was compiled). Raises ``RuntimeError`` when Newton does
    not converge in ``max_iter`` iterations.
    """
    import ngsolve as ng

    ng.SetNumThreads(1)
    t0 = time.perf_counter()
    M = ngsolve_mesh(mesh)
    fes = ng.VectorH1(M, order=2, dirichlet="bottom|top")
    form, how = _energy_form(fes, mu, bulk, compiled)
    free = np.array(list(fes.FreeDofs()), dtype=bool)
    gfu, lift = ng.GridFunction(fes), ng.GridFunction(fes)
    lift.Set(ng.CF(tuple(top_u)), definedon=M.Boundaries("top"))
    r, w = gfu.vec.CreateVector(), gfu.vec.CreateVector()
    setup = time.perf_counter() - t0
    t_tan = t_sol = 0.0
    n_fact = 0
    history: list[float] = []

    def assemble() -> None:
        """The tangent at gfu into ``form.mat``."""
        nonlocal t_tan
        t = time.perf_counter()
        form.AssembleLinearization(gfu.vec)
        t_tan += time.perf_counter() - t

    def factor_and_solve() -> None:
        """w = K⁻¹ r on the free unknowns: a new factorisation of the tangent."""
        nonlocal t_sol, n_fact
        t = time.perf_counter()
        inv = form.mat.Inverse(fes.FreeDofs(), inverse=INVERSE)
        w.data = inv * r
        t_sol += time.perf_counter() - t
        n_fact += 1

    t0 = time.perf_counter()
    # tangent predictor: K(0) dq = -(r(0) + K(0) lift) on the free unknowns
    form.Apply(gfu.vec, r)
    assemble()
    w.data = form.mat * lift.vec
    r.data += w
    ref = max(float(np.linalg.norm(r.FV().NumPy()[free])), np.finfo(float).tiny)
    factor_and_solve()
    gfu.vec.data = lift.vec - w
    for _ in range(max_iter + 1):
        form.Apply(gfu.vec, r)
        norm = float(np.linalg.norm(r.FV().NumPy()[free]))
        history.append(norm / ref)
        if norm <= rtol * ref:
            break
        if len(history) > max_iter:
            raise RuntimeError(f"NGSolve's Newton did not converge in {max_iter} iterations "
                               f"(relative residual {history[-1]:.3g})")
        assemble()
        factor_and_solve()
        gfu.vec.data -= w
    wall = time.perf_counter() - t0
    nv = int(mesh.t.max()) + 1
    u = np.column_stack([gfu.components[c].vec.FV().NumPy()[:nv] for c in range(3)])
    return {"u": u, "wall": wall, "setup_s": setup, "factorisations": n_fact,
            "s_per_newton": wall / n_fact, "tangent_assembly_s": t_tan / n_fact,
            "solve_s": t_sol / n_fact, "residuals": history, "inverse": INVERSE, "assembly": how,
            "ndof": fes.ndof, "version": ng.__version__}
