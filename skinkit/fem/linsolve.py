"""Pluggable sparse direct solvers for the tangent systems.

:func:`make` returns a solver object that is kept for a whole analysis: ``factor(K)``
factorises a new tangent, ``solve(b)`` back-substitutes (``b`` ``(n,)`` or ``(n, m)``:
one back-substitution per right-hand side, which is what makes direct-differentiation
sensitivities cheap). Solvers that exploit symmetry set ``upper = True`` and take only the
upper triangle (CSR), which the assembly then builds directly.

* ``"pardiso"`` — MKL PARDISO through the ``pypardiso`` package, symmetric indefinite
  (``mtype = -2``); the fill-reducing analysis is done once for the first tangent and
  reused, because the pattern never changes;
* ``"splu"`` — SciPy's SuperLU on the full matrix (always available);
* ``"auto"`` — PARDISO when installed, else SuperLU: on the two-core benchmark machine
  PARDISO factorises the ~10,000-dof 27-node tangent several times faster than SuperLU
  (``skinkit bench fem --linear splu`` shows the measurement).
"""

from __future__ import annotations

import ctypes
import importlib.util

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from skinkit.fem.errors import ModelError, SolverError

SOLVERS = ("auto", "pardiso", "splu")


def available() -> list[str]:
    """Solver names usable here, fastest first."""
    out = ["splu"]
    if importlib.util.find_spec("pypardiso") is not None:
        out.insert(0, "pardiso")
    return out


def resolve(name: str) -> str:
    """The concrete solver ``name`` stands for."""
    if name not in SOLVERS:
        raise ModelError("solver.linear", f"unknown linear solver {name!r}; choose from {SOLVERS}")
    if name == "auto":
        return available()[0]
    if name not in available():
        raise ModelError("solver.linear", f"linear solver {name!r} is not installed")
    return name


def _locate_mkl() -> None:
    """Point pypardiso at MKL's runtime library from the ``mkl`` wheel's file list.

    Without it pypardiso globs the whole environment for ``mkl_rt`` (about 2 s per solver).
    """
    import os
    if os.environ.get("PYPARDISO_MKL_RT"):
        return
    try:
        from importlib.metadata import files
        for f in files("mkl") or []:
            if "mkl_rt" in f.name:
                os.environ["PYPARDISO_MKL_RT"] = str(f.locate())
                return
    except Exception:  # no metadata: let pypardiso search as it does
        return


class SuperLUSolver:
    """SciPy SuperLU on the full matrix (one thread: :meth:`use_threads` does nothing)."""

    upper = False
    name = "splu"

    def __init__(self) -> None:
        self.lu = None

    def use_threads(self, n: int) -> None:
        """SuperLU is sequential: nothing to set."""

    def factor(self, K: sp.csr_matrix) -> None:
        """Factorise the tangent ``K`` (n, n); :class:`SolverError` when it is singular."""
        # the pattern is symmetric: minimum degree on A^T + A gives the least fill
        try:
            self.lu = spla.splu(K.tocsc(), permc_spec="MMD_AT_PLUS_A")
        except RuntimeError as exc:
            raise SolverError(f"the tangent is singular ({exc}); "
                              "is the body held against rigid motion?") from exc

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``K⁻¹ b`` for ``b`` (n,) or (n, k) with the last factorisation."""
        return self.lu.solve(np.asarray(b, dtype=float))


class PardisoSolver:
    """MKL PARDISO, real symmetric indefinite, upper triangle in CSR; analysis reused."""

    upper = True
    name = "pardiso"

    def __init__(self) -> None:
        _locate_mkl()
        import pypardiso
        # pypardiso locates and binds MKL's pardiso symbol; the calls are made here to keep
        # the symbolic analysis between factorisations (pypardiso redoes it every time)
        self._w = pypardiso.PyPardisoSolver(mtype=-2)
        self._pt = np.zeros(64, dtype=np.int64)
        self._iparm = np.zeros(64, dtype=np.int32)
        self._iparm[0] = 1      # iparm given explicitly
        self._iparm[1] = 2      # METIS nested dissection
        self._iparm[9] = 8      # pivot perturbation 1e-8
        self._iparm[10] = 0     # no scaling (symmetric indefinite default)
        self._iparm[12] = 0
        self._iparm[34] = 1     # zero-based indexing
        self._pattern = None
        self._K = None
        self._n = 0
        self._nthreads: int | None = None

    def use_threads(self, n: int) -> None:
        """Run every phase with ``n`` threads (before the first :meth:`factor`; default: MKL's
        count at the first call, one inside a solve's thread limit). A protocol solved alone
        while other cores wait gains here: on a 50,787-unknown two-pad mesh two threads took
        the prediction from 41 to 29 s (70 s against 89 with five parameters' derivatives); at
        7,395 unknowns the factorisation is too small to gain."""
        if self._pattern is not None and n != self._nthreads:
            raise SolverError("PARDISO's thread count is fixed once its analysis is made")
        self._nthreads = max(1, int(n))

    def _call(self, phase: int, K: sp.csr_matrix, b: np.ndarray | None = None) -> np.ndarray | None:
        # PARDISO crashes when its phases run with different thread counts (e.g. a factor
        # inside a caller's BLAS thread limit after an analysis outside it): pin the count
        # chosen at the analysis for every call, then restore the caller's
        lib = self._w.libmkl
        if self._nthreads is None:
            self._nthreads = max(1, int(lib.MKL_Get_Max_Threads()))
        prev = lib.MKL_Set_Num_Threads_Local(ctypes.c_int(self._nthreads))
        try:
            return self._call_pinned(phase, K, b)
        finally:
            lib.MKL_Set_Num_Threads_Local(ctypes.c_int(prev))

    def _call_pinned(self, phase: int, K: sp.csr_matrix, b: np.ndarray | None = None) -> np.ndarray | None:
        n = K.shape[0]
        nrhs = 1 if b is None or b.ndim == 1 else b.shape[1]
        bb = np.zeros(n) if b is None else np.asfortranarray(b, dtype=float)
        x = np.zeros_like(bb)
        err = ctypes.c_int32(0)
        i32 = ctypes.POINTER(ctypes.c_int32)
        f64 = ctypes.POINTER(ctypes.c_double)
        self._w._mkl_pardiso(
            self._pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)),
            ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(1)),
            ctypes.byref(ctypes.c_int32(-2)), ctypes.byref(ctypes.c_int32(phase)),
            ctypes.byref(ctypes.c_int32(n)), K.data.ctypes.data_as(f64),
            self._ia.ctypes.data_as(i32), self._ja.ctypes.data_as(i32),
            np.zeros(0, dtype=np.int32).ctypes.data_as(i32), ctypes.byref(ctypes.c_int32(nrhs)),
            self._iparm.ctypes.data_as(i32), ctypes.byref(ctypes.c_int32(0)),
            bb.ctypes.data_as(f64), x.ctypes.data_as(f64), ctypes.byref(err))
        if err.value != 0:
            raise SolverError(f"PARDISO failed in phase {phase} with error {err.value}")
        return np.ascontiguousarray(x) if b is not None else None

    def factor(self, K: sp.csr_matrix) -> None:
        """Factorise the tangent ``K`` (n, n; upper triangle), reusing an unchanged pattern's analysis."""
        K = K if K.has_sorted_indices else K.sorted_indices()
        first = self._pattern is None or self._n != K.shape[0] or \
            not (np.array_equal(self._pattern[0], K.indptr) and np.array_equal(self._pattern[1], K.indices))
        if first:
            if self._pattern is not None:
                self.free()
            self._pattern = (K.indptr.copy(), K.indices.copy())
            self._ia = K.indptr.astype(np.int32)
            self._ja = K.indices.astype(np.int32)
            self._n = K.shape[0]
            self._call(12, K)
        else:
            self._call(22, K)
        self._K = K

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``K⁻¹ b`` for ``b`` (n,) or (n, k) with the last factorisation."""
        return self._call(33, self._K, np.asarray(b, dtype=float))

    def free(self) -> None:
        """Release PARDISO's memory (the next :meth:`factor` analyses again)."""
        if self._pattern is not None and self._K is not None:
            try:
                self._call(-1, self._K)
            except SolverError:
                pass
        self._pattern = None

    def __del__(self) -> None:  # release MKL's memory with the solver
        try:
            self.free()
        except Exception:
            pass


def make(name: str = "auto"):
    """A persistent solver object for ``name`` (see :data:`SOLVERS`)."""
    real = resolve(name)
    return PardisoSolver() if real == "pardiso" else SuperLUSolver()
