"""Linear identification: IRF, damped-sinusoid fit, K, B, I (thesis 4.1.2)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import solve_toeplitz
from scipy.optimize import least_squares

from skinkit.sysid.checks import (
    WARN_MEMORIES,
    MemoryWarning,
    NonCausalWarning,
    PoorFitWarning,
    Signals,
    SysidError,
    check_irf_size,
    max_irf_lags,
    nonphysical,
    warn,
)
from skinkit.sysid.damped import DampedFit, fit_damped_sinusoid
from skinkit.sysid.irf import IRF, correlations, estimate_irf
from skinkit.sysid.lti import HOLDS, SecondOrder, simulate
from skinkit.sysid.metrics import vaf
from skinkit.sysid.record import as_signals
from skinkit.sysid.robot import RobotDynamics

#: longest memory tried by the automatic choice [s] (skin IRFs last < 0.25 s, thesis 4.2.1)
MAX_AUTO_MEMORY_S = 0.3
#: the automatic memory ends where the fitted envelope has fallen to this fraction
ENVELOPE_END = 1e-3
#: a damped-sinusoid fit accounting for less of the IRF's variance than this is poor [%]
POOR_FIT_VAF = 80.0


@dataclass
class LinearModel:
    """An identified linear force-to-position model.

    Attributes:
        total: identified robot-plus-skin dynamics (what :meth:`predict` simulates).
        skin: ``total`` with the robot's dynamics removed (``total`` without a robot).
        irf: the non-parametric IRF.
        damped: the damped-sinusoid fit to the IRF.
        rate_hz: sampling rate [Hz]; hold: input hold assumed ("foh"/"zoh"/"impulse").
        offset_m: position offset added to the simulated response [m].
        vaf_linear_pct: VAF of the parametric model's simulated output [%].
        vaf_irf_pct: VAF of the non-parametric IRF's prediction [%].
        se: standard errors of ``skin`` K, B, I (output-error Jacobian, white-noise approx.).
        burn_in: leading samples left out of every VAF (one memory length).
        issues: warnings raised while identifying (``"Name: message"``).
    """

    total: SecondOrder
    skin: SecondOrder
    irf: IRF
    damped: DampedFit
    rate_hz: float
    hold: str
    offset_m: float
    vaf_linear_pct: float
    vaf_irf_pct: float
    se: dict[str, float]
    burn_in: int
    n_samples: int
    force_mean_N: float
    position_mean_m: float
    robot: RobotDynamics | None = None
    refined: bool = False
    issues: list[str] = field(default_factory=list)

    def predict(self, force_N: np.ndarray) -> np.ndarray:
        """Position [m] ``(N,)`` for force ``(N,)`` [N], simulated with :mod:`scipy.signal`
        from equilibrium under the first force sample."""
        if not self.valid:
            raise SysidError("this linear model is not a stable under-damped system (see its "
                             "warnings); it cannot be simulated")
        h = self.hold if self.hold != "impulse" else "foh"
        return simulate(self.total, np.asarray(force_N, float), self.rate_hz, h) + self.offset_m

    @property
    def valid(self) -> bool:
        """True when the fit is a stable, under-damped mass-spring-damper."""
        t = self.total
        return bool(self.damped.underdamped and t.K > 0 and t.B > 0 and t.I > 0)

    @property
    def errors(self) -> list[str]:
        """Why ``skin`` K, B, I must not be reported as numbers (empty when they may): the
        fit is not a stable under-damped system, or a value is non-physical (e.g. a
        negative mass after removing more robot mass than the fit found in total)."""
        out = []
        if not self.valid:
            out.append("the IRF is not a stable under-damped mass-spring-damper, so K, B, I "
                       "are not meaningful")
        bad = nonphysical(self.skin.K, self.skin.B, self.skin.I)
        for key, unit, scale, robot_attr in (("K", "N/m", 1.0, "stiffness_N_per_m"),
                                             ("B", "N s/m", 1.0, "damping_Ns_per_m"),
                                             ("I", "g", 1e3, "mass_kg")):
            if key not in bad:
                continue
            msg = f"{key} = {getattr(self.skin, key) * scale:.4g} {unit}: {bad[key]}"
            removed = 0.0 if self.robot is None else getattr(self.robot, robot_attr)
            if removed:
                msg += (f" (robot {removed * scale:.4g} {unit} removed from the identified "
                        f"total {getattr(self.total, key) * scale:.4g} {unit})")
            out.append(msg)
        return out

    def to_dict(self) -> dict[str, Any]:
        """The linear model as a plain dict: K, B, I and their standard errors, gain, wn, damping, VAF."""
        return {
            "model": "linear", "valid": self.valid, "errors": self.errors,
            "K_N_per_m": self.skin.K, "B_Ns_per_m": self.skin.B, "I_kg": self.skin.I,
            "K_se_N_per_m": self.se["K"], "B_se_Ns_per_m": self.se["B"], "I_se_kg": self.se["I"],
            "gain_m_per_N": self.skin.gain_m_per_N if self.skin.K > 0 else float("nan"),
            "wn_rad_s": self.skin.wn_rad_s if self.skin.K * self.skin.I > 0 else float("nan"),
            "zeta": self.skin.zeta if self.skin.K * self.skin.I > 0 else float("nan"),
            "vaf_linear_pct": self.vaf_linear_pct, "vaf_irf_pct": self.vaf_irf_pct,
            "irf_memory_s": self.irf.memory_s, "irf_rank": self.irf.rank,
            "irf_two_sided": self.irf.two_sided,
            "A1_m_per_Ns": self.damped.A1, "A2_rad_per_s": self.damped.A2,
            "A3_per_s": self.damped.A3, "vaf_irf_fit_pct": self.damped.vaf_pct,
            "total": self.total.to_dict(),
            "robot": None if self.robot is None else self.robot.to_dict(),
            "rate_hz": self.rate_hz, "n_samples": self.n_samples, "hold": self.hold,
            "refined": self.refined, "force_mean_N": self.force_mean_N,
            "position_mean_m": self.position_mean_m, "warnings": list(self.issues),
        }


def auto_memory(sig: Signals, two_sided: bool, hold: str) -> float:
    """Memory [s]: where the damped sinusoid fitted to a long IRF has decayed to
    ``ENVELOPE_END`` of its start; where no sinusoid fits, 1.5 x the last lag whose IRF
    value is significant (3 standard deviations)."""
    # at most the lags allowed (a fast-sampled record gets a shorter automatic memory)
    lags = max_irf_lags() // (2 if two_sided else 1)
    m0 = min(MAX_AUTO_MEMORY_S, (sig.n / WARN_MEMORIES - 1) / sig.rate_hz, (lags - 1) / sig.rate_hz)
    if m0 * sig.rate_hz < 8:
        raise SysidError(f"record of {sig.n} samples is too short for an automatic IRF memory")
    # a first, cheap estimate: Levinson solution with a ridge (1 % of the input variance)
    # in place of the eigen-decomposition, enough to see where the IRF decays
    x = sig.force_N - sig.force_N.mean()
    n0 = int(round(m0 * sig.rate_hz)) + 1
    rxx, phi = correlations(x, sig.position_m - sig.position_m.mean(), n0)
    col = rxx.copy()
    col[0] *= 1.0 + 1e-2
    h0 = solve_toeplitz(col, phi) * sig.rate_hz
    quick = IRF(np.arange(n0) / sig.rate_hz, h0, np.zeros(n0), sig.rate_hz, n0, np.zeros(n0),
                float("nan"))
    fit = fit_damped_sinusoid(quick, hold)
    if fit.underdamped and fit.vaf_pct >= POOR_FIT_VAF:
        mem = np.log(1.0 / ENVELOPE_END) / -fit.A3
    else:
        irf = estimate_irf(sig.force_N, sig.position_m, sig.rate_hz, m0, two_sided)
        h = irf.h[irf.n_neg:]
        sig_lags = np.flatnonzero(np.abs(h) > 3 * irf.h_std[irf.n_neg:])
        mem = 1.5 * (sig_lags[-1] if sig_lags.size else h.size - 1) / sig.rate_hz
    return float(np.clip(mem, 8 / sig.rate_hz, m0))


def _check_causality(sig: Signals, memory_s: float) -> None:
    m = int(round(memory_s * sig.rate_hz)) + 1
    _, phi = correlations(sig.force_N - sig.force_N.mean(), sig.position_m - sig.position_m.mean(),
                          m, m - 1)
    lag = (int(np.argmax(np.abs(phi))) - (m - 1)) / sig.rate_hz
    pos = float(np.sum(phi[m - 1:] ** 2))
    neg = float(np.sum(phi[:m - 1] ** 2))
    if neg > pos:
        warn(NonCausalWarning, f"the force-position cross-correlation is larger at negative lags "
             f"(peak at {lag:.4g} s): position leads force, so force is probably not the input "
             "(a displacement-controlled test?)", sig.issues)


#: the IRF's last tenth may hold at most this fraction of its peak (significant values only)
TAIL_FRACTION = 0.2


def _check_decay(irf: IRF, sig: Signals) -> None:
    h = irf.h[irf.n_neg:]
    sd = irf.h_std[irf.n_neg:]
    tail = slice(int(0.9 * h.size), None)
    peak = float(np.max(np.abs(h)))
    big = (np.abs(h[tail]) > TAIL_FRACTION * peak) & (np.abs(h[tail]) > 3 * sd[tail])
    if big.any():
        warn(MemoryWarning, f"the IRF has not decayed by the end of its {irf.memory_s:.4g} s "
             f"memory (last tenth reaches {100 * np.max(np.abs(h[tail])) / peak:.3g} % of the "
             "peak): lengthen the memory, or the response drifts/creeps beyond a short IRF",
             sig.issues)


def _se(system: SecondOrder, f: np.ndarray, resid_var: float, rate: float, hold: str,
        burn: int) -> np.ndarray:
    """Standard errors of (K, B, I) from the output-error Jacobian: sigma^2 (J^T J)^-1."""
    p = np.array([system.K, system.B, system.I])
    base = simulate(SecondOrder(*p), f, rate, hold)[burn:]
    J = np.empty((base.size, 3))
    for j in range(3):
        q = p.copy()
        dq = 1e-6 * abs(p[j]) or 1e-12
        q[j] += dq
        d = simulate(SecondOrder(*q), f, rate, hold)[burn:] - base
        J[:, j] = (d - d.mean()) / dq
    try:
        cov = resid_var * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return np.full(3, np.nan)
    return np.sqrt(np.abs(np.diag(cov)))


def refine_output_error(system: SecondOrder, f: np.ndarray, y: np.ndarray, rate: float,
                        hold: str, burn: int) -> SecondOrder:
    """Least-squares fit of K, B, I to the measured output by simulation (prediction-error
    method), started from ``system``; the offset is profiled out."""
    p0 = np.array([system.K, system.B, system.I])
    yy = y[burn:]

    def resid(q: np.ndarray) -> np.ndarray:
        r = simulate(SecondOrder(*(p0 * np.exp(q))), f, rate, hold)[burn:] - yy
        return r - r.mean()

    sol = least_squares(resid, np.zeros(3), method="lm")
    return SecondOrder(*(p0 * np.exp(sol.x)))


def identify_signals(sig: Signals, memory_s: float | None = None, *, two_sided: bool = False,
                     hold: str = "foh", robot: RobotDynamics | None = None,
                     refine: bool = False, rank: int | None = None) -> LinearModel:
    """:func:`identify_linear` on already checked :class:`Signals`."""
    if hold not in HOLDS:
        raise SysidError(f"hold must be one of {', '.join(HOLDS)}, got {hold!r}")
    if memory_s is None:
        memory_s = auto_memory(sig, two_sided, hold)
    n_pos = int(round(memory_s * sig.rate_hz)) + 1
    check_irf_size(2 * n_pos - 1 if two_sided else n_pos, sig.rate_hz, memory_s)  # before allocating
    _check_causality(sig, memory_s)
    f, y, rate = sig.force_N, sig.position_m, sig.rate_hz
    irf = estimate_irf(f, y, rate, memory_s, two_sided, rank)
    _check_decay(irf, sig)
    fit = fit_damped_sinusoid(irf, hold)
    if not fit.underdamped:
        warn(PoorFitWarning, f"the IRF is not an under-damped sinusoid (A1={fit.A1:.3g}, "
             f"A2={fit.A2:.3g} rad/s, A3={fit.A3:.3g} /s): K, B, I are not meaningful",
             sig.issues)
    elif fit.vaf_pct < POOR_FIT_VAF:
        warn(PoorFitWarning, f"the damped sinusoid accounts for only {fit.vaf_pct:.3g} % of the "
             "IRF's variance", sig.issues)
    total = fit.system
    burn = int(round(memory_s * rate)) + 1
    sim_hold = hold if hold != "impulse" else "foh"
    if refine and total.K > 0 and total.B > 0 and total.I > 0:
        total = refine_output_error(total, f, y, rate, sim_hold, burn)
    fm, ym = float(f.mean()), float(y.mean())
    y_irf = irf.predict(f - fm)
    vaf_irf = vaf(y[burn:], y_irf[burn:])
    if total.K > 0 and total.B > 0 and total.I > 0:
        y_sim = simulate(total, f, rate, sim_hold)
        offset = float(np.mean(y[burn:] - y_sim[burn:]))
        resid = y[burn:] - y_sim[burn:] - offset
        vaf_lin = vaf(y[burn:], y_sim[burn:])
        se_total = _se(total, f, float(np.var(resid)), rate, sim_hold, burn)
    else:  # an unstable or non-physical fit cannot be simulated; the warning above says why
        offset, vaf_lin, se_total = float("nan"), float("nan"), np.full(3, np.nan)
    if robot is not None:
        skin = robot.remove(total, ym)
        se_total = se_total * robot.factor(ym)
    else:
        skin = total
    se = dict(zip(("K", "B", "I"), (float(v) for v in se_total), strict=True))
    return LinearModel(total=total, skin=skin, irf=irf, damped=fit, rate_hz=rate, hold=hold,
                       offset_m=offset, vaf_linear_pct=vaf_lin, vaf_irf_pct=vaf_irf, se=se,
                       burn_in=burn, n_samples=sig.n, force_mean_N=fm, position_mean_m=ym,
                       robot=robot, refined=refine, issues=sig.issues)


def identify_linear(force_N: Any, position_m: Any = None, rate_hz: float | None = None,
                    memory_s: float | None = None, *, time_s: Any = None, two_sided: bool = False,
                    hold: str = "foh", robot: RobotDynamics | None = None, refine: bool = False,
                    rank: int | None = None, flags: Any = None,
                    force_limit_N: float | None = None, axis: int | str = 2) -> LinearModel:
    """Identify K, B, I from a stochastic force record.

    Args:
        force_N: ``(N,)`` input force [N], or a :class:`~skinkit.schemas.RobotRecord` (then
            its ``tip_force`` and ``tip_position`` along ``axis``, times and flags are used).
        position_m: ``(N,)`` output position [m].
        rate_hz: sampling rate [Hz] (or give ``time_s``, ``(N,)`` [s]).
        memory_s: IRF memory [s]; ``None`` chooses it from the IRF's decay.
        two_sided: also estimate negative lags (a non-causal check).
        hold: how the force varies between samples: ``"foh"`` (linearly, a measured smooth
            force), ``"zoh"`` (held, a commanded force) or ``"impulse"`` (the thesis's plain
            sampling of ``h(t)``).
        robot: the robot's dynamics to remove from the estimate (``skin`` in the result).
        refine: after the damped-sinusoid fit, refine K, B, I by output-error least squares.
        rank: number of pseudo-inverse terms (default: minimum description length).
        flags: ``(N,)`` RobotRecord flags (saturation); force_limit_N: actuator limit [N].
        axis: tip axis of a RobotRecord (0/1/2 or "x"/"y"/"z"; default z, the normal).

    Returns:
        LinearModel; its ``issues`` list the warnings raised.
    """
    sig = as_signals(force_N, position_m, rate_hz, time_s, memory_s, flags, force_limit_N, axis)
    return identify_signals(sig, memory_s, two_sided=two_sided, hold=hold, robot=robot,
                            refine=refine, rank=rank)
