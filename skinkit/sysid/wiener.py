"""Wiener model: unit-DC-gain second-order dynamics followed by a static nonlinearity.

Thesis 4.1.2: the linear IRF divided by its DC compliance predicts an output in newtons,
``x``; the nonlinearity ``Y = C1 (1 - exp(-C2 x))`` (Eq. 4.9) is fitted between ``x`` and
the measured position, and the linear part is re-estimated, until the VAF converges. The
dynamics are then the scaled inertia ``Is = I/K`` [s^2] and damping ``Bs = B/K`` [s].

The thesis re-estimates the IRF through the inverse nonlinearity (``update="inverse"``);
inverting the exponential amplifies noise near its asymptote (y -> C1), so by default the
linear step instead re-fits Is and Bs to the measured output through the current
nonlinearity (output error). A final joint least-squares pass over Is, Bs and the
nonlinearity gives the estimates (``joint=False`` keeps the iteration's own).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from skinkit.sysid.checks import PoorFitWarning, Signals, SysidError, warn
from skinkit.sysid.linear import LinearModel, identify_signals
from skinkit.sysid.lti import SecondOrder, simulate
from skinkit.sysid.metrics import vaf
from skinkit.sysid.nonlinearity import StaticNonlinearity, fit_exponential, fit_polynomial
from skinkit.sysid.record import as_signals


@dataclass
class WienerModel:
    """An identified Wiener model.

    Attributes:
        Is_s2, Bs_s: scaled inertia [s^2] and damping [s] of the unit-DC-gain dynamics
            (robot plus skin: the robot's dynamics cannot be removed once K is folded
            into the nonlinearity).
        nonlinearity: the static nonlinearity from ``x`` [N] to position [m].
        linear: the linear model the iteration started from (its VAF is ``vaf_linear_pct``).
        vaf_wiener_pct: VAF of the Wiener model's simulated output [%].
        vaf_history: VAF after each iteration [%]; iterations: how many were run.
        se: standard errors of Is, Bs, C1, C2 from the joint fit's Jacobian (white-noise
            approximation; NaN without the joint pass).
    """

    Is_s2: float
    Bs_s: float
    nonlinearity: StaticNonlinearity
    linear: LinearModel
    vaf_wiener_pct: float
    vaf_history: list[float]
    rate_hz: float
    hold: str
    converged: bool
    se: dict[str, float] = field(default_factory=dict)
    issues: list[str] = field(default_factory=list)

    @property
    def dynamics(self) -> SecondOrder:
        """The identified second-order dynamics (from the scaled Is and Bs)."""
        return SecondOrder.from_scaled(self.Is_s2, self.Bs_s)

    @property
    def iterations(self) -> int:
        """Number of iterations made."""
        return len(self.vaf_history)

    def intermediate(self, force_N: np.ndarray) -> np.ndarray:
        """Linear-part output ``x`` [N] ``(N,)`` for force ``(N,)`` [N]."""
        return simulate(self.dynamics, np.asarray(force_N, float), self.rate_hz, self.hold)

    def predict(self, force_N: np.ndarray) -> np.ndarray:
        """Position [m] ``(N,)``, simulated with :mod:`scipy.signal` from equilibrium."""
        return self.nonlinearity(self.intermediate(force_N))

    def to_dict(self) -> dict[str, Any]:
        """The linear model's dict with the Wiener fields, the iterations and the nonlinearity added."""
        d = self.linear.to_dict()
        d.update({"model": "wiener", "Is_s2": self.Is_s2, "Bs_s": self.Bs_s,
                  "vaf_wiener_pct": self.vaf_wiener_pct, "iterations": self.iterations,
                  "vaf_history_pct": list(self.vaf_history), "converged": self.converged,
                  "nonlinearity": self.nonlinearity.to_dict(), "warnings": list(self.issues)})
        d["Is_se_s2"], d["Bs_se_s"] = self.se.get("Is", np.nan), self.se.get("Bs", np.nan)
        if self.nonlinearity.kind == "exponential":
            d["C1_m"], d["C2_per_N"] = self.nonlinearity.params[:2]
            d["C1_se_m"], d["C2_se_per_N"] = self.se.get("C1", np.nan), self.se.get("C2", np.nan)
        return d


def _fit_nl(kind: str, x: np.ndarray, y: np.ndarray, degree: int, fit_offset: bool,
            start: StaticNonlinearity | None) -> StaticNonlinearity:
    if kind == "exponential":
        return fit_exponential(x, y, fit_offset, start)
    return fit_polynomial(x, y, degree)


def identify_wiener_signals(sig: Signals, memory_s: float | None = None, *,
                            nonlinearity: str = "exponential", degree: int = 3,
                            fit_offset: bool = False, max_iter: int = 20, tol_pct: float = 1e-3,
                            joint: bool = True, hold: str = "foh", update: str = "output_error",
                            linear: LinearModel | None = None, **linear_kw: Any) -> WienerModel:
    """:func:`identify_wiener` on already checked :class:`Signals`."""
    if update not in ("output_error", "inverse"):
        raise SysidError(f"update must be 'output_error' or 'inverse', got {update!r}")
    if update == "inverse" and nonlinearity != "exponential":
        raise SysidError("the inverse update needs the invertible exponential nonlinearity")
    if nonlinearity not in ("exponential", "polynomial"):
        raise SysidError(f"nonlinearity must be 'exponential' or 'polynomial', got {nonlinearity!r}")
    lin = linear if linear is not None else identify_signals(sig, memory_s, hold=hold, **linear_kw)
    f, y, rate = sig.force_N, sig.position_m, sig.rate_hz
    hold = lin.hold if lin.hold != "impulse" else "foh"
    burn = lin.burn_in
    yy = y[burn:]
    if not lin.valid:
        raise SysidError("the linear model is not a stable under-damped system, so no Wiener "
                         "model can start from it (see its warnings)")
    q = np.log([lin.total.Is_s2, lin.total.Bs_s])

    def x_of(qq: np.ndarray) -> np.ndarray:
        return simulate(SecondOrder.from_scaled(*np.exp(qq)), f, rate, hold)

    g: StaticNonlinearity | None = None
    history: list[float] = []
    converged = False
    for _ in range(max_iter):
        x = x_of(q)
        g = _fit_nl(nonlinearity, x[burn:], yy, degree, fit_offset, g)
        history.append(vaf(yy, g(x[burn:])))
        if len(history) > 1 and abs(history[-1] - history[-2]) < tol_pct:
            converged = True
            break
        if update == "inverse":
            q = _inverse_update(g, sig, lin, q)
        else:
            g_now = g
            sol = least_squares(lambda qq, g_now=g_now: g_now(x_of(qq)[burn:]) - yy, q,
                                method="lm")
            q = sol.x
    assert g is not None
    se = {"Is": float("nan"), "Bs": float("nan"), "C1": float("nan"), "C2": float("nan")}
    if joint:
        q, g, se_j = _joint(q, g, x_of, yy, burn, nonlinearity, degree, fit_offset)
        se.update(se_j)
        history.append(vaf(yy, g(x_of(q)[burn:])))
    if history[-1] < lin.vaf_linear_pct:
        hint = "" if fit_offset or nonlinearity != "exponential" else (
            "; is position 0 the unloaded skin surface? if not, fit an offset "
            "(fit_offset=True, --fit-offset)")
        warn(PoorFitWarning, f"the Wiener model accounts for less variance ({history[-1]:.4g} %) "
             f"than the linear model ({lin.vaf_linear_pct:.4g} %){hint}", sig.issues)
    Is, Bs = (float(v) for v in np.exp(q))
    return WienerModel(Is_s2=Is, Bs_s=Bs, nonlinearity=g, linear=lin,
                       vaf_wiener_pct=history[-1], vaf_history=history, rate_hz=rate, hold=hold,
                       converged=converged, se=se, issues=sig.issues)


def _inverse_update(g: StaticNonlinearity, sig: Signals, lin: LinearModel,
                    q: np.ndarray) -> np.ndarray:
    """Thesis update: map the measured output back through the inverse nonlinearity and
    re-identify the (unit-DC-gain) linear dynamics from force to that signal."""
    c1, c2, y0 = g.params
    u = np.clip(1.0 - (sig.position_m - y0) / c1, 1e-6, None)  # the asymptote is not crossed
    z = -np.log(u) / c2
    zsig = Signals(sig.force_N, z, sig.rate_hz, sig.t0_s, [])
    m = identify_signals(zsig, lin.irf.memory_s, hold=lin.hold, two_sided=lin.irf.two_sided)
    if not m.valid:
        return q
    return np.log([m.total.Is_s2, m.total.Bs_s])


def _se(sol: Any, n_par: int) -> np.ndarray:
    """Standard errors sigma^2 (J^T J)^-1 of a least-squares solution (white residual)."""
    r = sol.fun
    dof = max(r.size - n_par, 1)  # n_par may exceed the Jacobian's columns (projected ones)
    try:
        cov = float(r @ r) / dof * np.linalg.inv(sol.jac.T @ sol.jac)
    except np.linalg.LinAlgError:
        return np.full(n_par, np.nan)
    return np.sqrt(np.abs(np.diag(cov)))


def _joint(q: np.ndarray, g: StaticNonlinearity, x_of: Any, yy: np.ndarray, burn: int,
           kind: str, degree: int, fit_offset: bool
           ) -> tuple[np.ndarray, StaticNonlinearity, dict[str, float]]:
    """Joint least squares over the dynamics and the nonlinearity (polynomial coefficients,
    being linear, are solved exactly inside each residual). Returns the log scaled
    parameters, the nonlinearity and standard errors (Is, Bs, and C1, C2)."""
    if kind == "polynomial":
        def resid(qq: np.ndarray) -> np.ndarray:
            x = x_of(qq)[burn:]
            return np.polyval(np.polyfit(x, yy, degree), x) - yy

        sol = least_squares(resid, q, method="lm")
        x = x_of(sol.x)[burn:]
        # variable projection: the Jacobian covers Is, Bs; the dof also pay for the coefficients
        e = _se(sol, 2 + degree + 1)[:2] * np.exp(sol.x)
        return sol.x, fit_polynomial(x, yy, degree), {"Is": float(e[0]), "Bs": float(e[1])}
    n_nl = 3 if fit_offset else 2
    p0 = np.concatenate([q, g.params[:n_nl]])

    def resid_e(p: np.ndarray) -> np.ndarray:
        gg = StaticNonlinearity("exponential", (p[2], p[3], p[4] if fit_offset else 0.0))
        return gg(x_of(p[:2])[burn:]) - yy

    scale = np.concatenate([[1.0, 1.0], np.abs(p0[2:]) + 1e-12])
    sol = least_squares(resid_e, p0, method="lm", x_scale=scale)
    p = sol.x
    e = _se(sol, p.size)
    se = {"Is": float(e[0] * np.exp(p[0])), "Bs": float(e[1] * np.exp(p[1])),
          "C1": float(e[2]), "C2": float(e[3])}
    return p[:2], StaticNonlinearity("exponential", (float(p[2]), float(p[3]),
                                                     float(p[4]) if fit_offset else 0.0)), se


def identify_wiener(force_N: Any, position_m: Any = None, rate_hz: float | None = None,
                    memory_s: float | None = None, *, time_s: Any = None,
                    nonlinearity: str = "exponential", degree: int = 3, fit_offset: bool = False,
                    max_iter: int = 20, tol_pct: float = 1e-3, joint: bool = True,
                    hold: str = "foh", update: str = "output_error", flags: Any = None,
                    force_limit_N: float | None = None, axis: int | str = 2,
                    **linear_kw: Any) -> WienerModel:
    """Identify a Wiener model (thesis Eq. 4.9 nonlinearity by default).

    Args:
        force_N: ``(N,)`` force [N] including its mean (the nonlinearity sees absolute force).
        position_m: ``(N,)`` position [m] from the unloaded surface (``Y = 0`` at ``x = 0``;
            set ``fit_offset`` when the zero is unknown).
        rate_hz / time_s / memory_s / hold / flags / force_limit_N: as :func:`identify_linear`.
        nonlinearity: ``"exponential"`` (``C1 (1 - exp(-C2 x))``) or ``"polynomial"``.
        degree: polynomial degree.
        max_iter, tol_pct: iterate until the VAF changes by less than ``tol_pct`` [%].
        joint: finish with a joint least-squares pass over dynamics and nonlinearity.
        update: how each iteration re-estimates the linear part: ``"output_error"`` (fit
            Is, Bs through the current nonlinearity) or ``"inverse"`` (the thesis's: IRF
            from force to the output mapped through the inverse nonlinearity).
        **linear_kw: passed to the linear identification (``two_sided``, ``rank``, ...).
    """
    sig = as_signals(force_N, position_m, rate_hz, time_s, memory_s, flags, force_limit_N, axis)
    return identify_wiener_signals(sig, memory_s, nonlinearity=nonlinearity, degree=degree,
                                   fit_offset=fit_offset, max_iter=max_iter, tol_pct=tol_pct,
                                   joint=joint, hold=hold, update=update, **linear_kw)
