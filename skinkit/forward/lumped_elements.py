"""Quasi-static uniaxial lumped elements: elastic laws, the QLV (Prony) filter, preconditioning.

Every function is complex-safe (no ``abs``, ``max`` or comparisons on values that carry a
parameter), so the lumped forward model differentiates them by the complex step. The
coordinate ``u`` [m] and force ``f`` [N] are signed along the model's loading direction.

* Elastic element Fe(u): ``linear`` k u; ``exponential`` (Fung) a (exp(b u) − 1);
  ``polynomial`` Σⱼ cⱼ uʲ (j = 1..n).
* QLV: f = g∞ Fe + Σᵢ gᵢ hᵢ, hᵢⁿ = eᵢ hᵢⁿ⁻¹ + βᵢ (Feⁿ − Feⁿ⁻¹), eᵢ = exp(−Δt/τᵢ),
  βᵢ = τᵢ (1 − eᵢ)/Δt (exact for Fe piecewise linear in time, as
  :mod:`skinkit.fem.viscoelastic`). The record starts relaxed under its first sample
  (hᵢ⁰ = 0, so f⁰ = g∞ Fe⁰ — the steady state of the filter).
* Preconditioning: Fe is scaled by φ(t). Cycles form: φ = 1 − softening (1 − exp(−A(t)/cycles)),
  A(t) the loading strokes so far (the increases of |drive| summed over the session's protocols
  in order, each protocol starting from the unloaded skin) over m_ref, the session's largest
  |drive|. Largest-load form: φ = 1 − softening · m(t)/m_ref, m the largest |drive| so far.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy import signal

from skinkit.errors import ForwardError

#: elastic element -> its parameters (polynomial: c1, c2, ... as many as given)
ELASTIC_PARAMETERS: dict[str, tuple[str, ...]] = {"linear": ("k",), "exponential": ("a", "b"),
                                                  "polynomial": ()}
#: Newton iterations allowed per sample when inverting a polynomial element
_NEWTON_MAX = 60


def poly_names(given: Sequence[str]) -> list[str]:
    """The polynomial coefficients ``c1 .. cn`` named in ``given``, checked contiguous."""
    cs = sorted((n for n in given if n.startswith("c") and n[1:].isdigit()), key=lambda n: int(n[1:]))
    want = [f"c{j}" for j in range(1, len(cs) + 1)]
    if not cs or cs != want:
        raise ForwardError("lumped.parameters", f"a polynomial element needs coefficients c1..cn "
                           f"without gaps, got {sorted(given)}")
    return want


def elastic_force(kind: str, p: Mapping[str, Any], u: np.ndarray) -> np.ndarray:
    """Fe(u) [N] of the element ``kind`` with parameters ``p`` (SI) at ``u`` [m], any shape."""
    if kind == "linear":
        return p["k"] * u
    if kind == "exponential":
        if not (np.iscomplexobj(u) or np.iscomplexobj(p["a"]) or np.iscomplexobj(p["b"])):
            return p["a"] * np.expm1(p["b"] * u)     # accurate near u = 0
        return p["a"] * (np.exp(p["b"] * u) - 1)
    out = 0 * u
    for j in range(len(p), 0, -1):                    # Horner: c1 u + c2 u² + ... + cn uⁿ
        out = (out + p[f"c{j}"]) * u
    return out


def elastic_slope(kind: str, p: Mapping[str, Any], u: np.ndarray) -> np.ndarray:
    """dFe/du [N/m] at ``u``."""
    if kind == "linear":
        return p["k"] + 0 * u
    if kind == "exponential":
        return p["a"] * p["b"] * np.exp(p["b"] * u)
    out = 0 * u
    for j in range(len(p), 0, -1):
        out = out * u + j * p[f"c{j}"]
    return out


def elastic_inverse(kind: str, p: Mapping[str, Any], f: np.ndarray, entry: str = "lumped") -> np.ndarray:
    """u [m] with Fe(u) = ``f`` [N] (closed form, or Newton per sample for a polynomial).

    Raises :class:`ForwardError` naming ``entry`` when a force lies outside the element's
    range (below −a for the exponential) or a polynomial element is not increasing there."""
    if kind == "linear":
        if np.real(p["k"]) == 0:
            raise ForwardError("lumped.parameters.k", "a zero stiffness cannot be driven by a force")
        return f / p["k"]
    if kind == "exponential":
        r = f / p["a"]
        if np.real(p["b"]) == 0 or np.any(np.real(r) <= -1):
            raise ForwardError(entry, f"a force of {np.min(np.real(f)):.4g} N lies below the exponential "
                               f"element's limit -a = {-np.real(p['a']):.4g} N (or b = 0)")
        return np.log1p(r) / p["b"]
    c1 = p["c1"]
    u = f / c1 if np.real(c1) != 0 else 0 * f
    scale = np.max(np.abs(np.real(f))) + 1e-300
    for _ in range(_NEWTON_MAX):
        k = elastic_slope(kind, p, u)
        if np.any(np.real(k) <= 0):
            raise ForwardError(entry, "the polynomial element is not increasing over the forces it must "
                               "carry; it cannot be driven by a force")
        du = (elastic_force(kind, p, u) - f) / k
        u = u - du
        if np.max(np.abs(np.real(du) * np.real(k))) <= 1e-14 * scale:
            # one more step: the imaginary (derivative) part converges with the real part
            return u - (elastic_force(kind, p, u) - f) / elastic_slope(kind, p, u)
    raise ForwardError(entry, f"Newton did not converge inverting the polynomial element in "
                       f"{_NEWTON_MAX} iterations")


# -- QLV -------------------------------------------------------------------------------------
def _uniform(t: np.ndarray) -> bool:
    dt = np.diff(t)
    return dt.size > 0 and float(np.ptp(dt)) <= 1e-9 * float(np.mean(dt))


def _step_factors(dt: np.ndarray, tau: Any) -> tuple[np.ndarray, np.ndarray]:
    x = dt / tau
    e = np.exp(-x)
    return e, -np.expm1(-x) / x if not np.iscomplexobj(x) else (1 - e) / x


def _qlv_tf(g: Sequence[Any], tau: Sequence[Any], dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(num, den)`` in powers of z⁻¹ of f = H(z) Fe for a uniform step ``dt``."""
    ginf = 1 - sum(g)
    den = np.array([1.0 + 0j * ginf])
    terms = []
    for gi, ti in zip(g, tau, strict=True):
        e, beta = _step_factors(np.asarray(dt), ti)
        terms.append((gi, e, beta))
        den = np.convolve(den, [1, -e])
    num = ginf * den
    for i, (gi, _, beta) in enumerate(terms):
        rest = np.array([1.0 + 0j * ginf])
        for j, (_, ej, _) in enumerate(terms):
            if j != i:
                rest = np.convolve(rest, [1, -ej])
        part = gi * beta * np.convolve([1, -1], rest)
        num = num + np.concatenate([part, np.zeros(num.size - part.size)])
    if not any(np.iscomplexobj(a) and np.any(np.imag(a)) for a in (num, den)):
        num, den = np.real(num), np.real(den)
    return num, den


def qlv(t: np.ndarray, fe: np.ndarray, g: Sequence[Any], tau: Sequence[Any]) -> np.ndarray:
    """Force ``(T,)`` of the QLV element whose elastic force is ``fe`` ``(T,)`` at ``t`` [s]."""
    if not len(g):
        return fe * 1.0
    ginf = 1 - sum(g)
    if _uniform(t):
        # each term's exact recurrence h[n] = e h[n-1] + β Δfe[n-1] as a first-order filter, in
        # parallel: a product-form transfer function with poles near 1 (τ ≫ dt) loses some
        # 1e-10 of the force to rounding, enough to spoil differences of the prediction
        step = float(np.mean(np.diff(t)))
        x = np.concatenate([np.diff(fe), 0 * fe[:1]])
        out = ginf * fe
        for gi, ti in zip(g, tau, strict=True):
            e, beta = _step_factors(np.asarray(step), ti)
            out = out + gi * signal.lfilter([0 * beta, beta], [1 + 0 * e, -e], x)
        return out
    dt = np.diff(t)
    out = ginf * fe
    dfe = np.diff(fe)
    for gi, ti in zip(g, tau, strict=True):
        e, beta = _step_factors(dt, ti)
        h = np.zeros(len(t), dtype=np.result_type(fe, e, gi))
        for n in range(1, len(t)):      # the exact recurrence, step by step
            h[n] = e[n - 1] * h[n - 1] + beta[n - 1] * dfe[n - 1]
        out = out + gi * h
    return out


def qlv_inverse(t: np.ndarray, f: np.ndarray, g: Sequence[Any], tau: Sequence[Any]) -> np.ndarray:
    """Elastic force ``(T,)`` whose QLV response is ``f`` ``(T,)`` (the inverse of :func:`qlv`)."""
    if not len(g):
        return f * 1.0
    ginf = 1 - sum(g)
    if _uniform(t):
        num, den = _qlv_tf(g, tau, float(np.mean(np.diff(t))))
        # the inverse (creep) filter is stable: the zeros of H lie inside the unit circle
        return f[0] / ginf + signal.lfilter(den, num, f - f[0])
    dt = np.diff(t)
    fac = [_step_factors(dt, ti) for ti in tau]
    n_terms = len(g)
    h = [0 * f[0]] * n_terms
    fe = np.zeros(len(t), dtype=np.result_type(f, *fac[0], *g))
    fe[0] = f[0] / ginf
    for n in range(1, len(t)):
        # f = g∞ Fe + Σ g (e h + β (Fe − Fe_prev)), solved for Fe
        a = sum(g[i] * (fac[i][0][n - 1] * h[i] - fac[i][1][n - 1] * fe[n - 1]) for i in range(n_terms))
        b = ginf + sum(g[i] * fac[i][1][n - 1] for i in range(n_terms))
        fe[n] = (f[n] - a) / b
        h = [fac[i][0][n - 1] * h[i] + fac[i][1][n - 1] * (fe[n] - fe[n - 1]) for i in range(n_terms)]
    return fe


#: |c| times the element's largest stiffness below which the series compliance is linearised:
#: the neglected terms, (c k)² relative, are then under double rounding
LINEAR_COMPLIANCE = 1e-8


def _newton_scalar(r: Any, drdu: Any, u: Any, scale: float, entry: str) -> Any:
    for _ in range(_NEWTON_MAX):
        k = drdu(u)
        if np.real(k) <= 0:
            raise ForwardError(entry, "the series compliance and the element admit no unique tip position")
        du = r(u) / k
        u = u - du
        if abs(np.real(du)) <= 1e-14 * scale:
            return u - r(u) / drdu(u)
    raise ForwardError(entry, f"Newton did not converge in {_NEWTON_MAX} iterations")


def series_solve(t: np.ndarray, u_rec: np.ndarray, phi: Any, kind: str, p: Mapping[str, Any],
                 g: Sequence[Any], tau: Sequence[Any], c: Any, entry: str) -> tuple[np.ndarray, np.ndarray]:
    """Tip position u and force f ``(T,)`` when the recorded drive ``u_rec`` [m] is the tip
    position plus a series compliance ``c`` [m/N] times the force: u + c f(u) = u_rec, f the
    QLV response of φ Fe(u). Newton per sample (vectorised over samples without relaxation)."""
    scale = float(np.max(np.abs(np.real(u_rec)))) + 1e-300
    phi = phi + 0 * u_rec
    slope = phi * elastic_slope(kind, p, u_rec)
    k_max = float(np.max(np.abs(slope))) if len(u_rec) else 0.0
    if abs(c) * k_max <= LINEAR_COMPLIANCE:
        # a compliance whose deflection is far below the tip's motion (its null, or the complex
        # step that differentiates it there): to first order u = u_rec − c f0 and f = f0 − c ·
        # QLV[φ Fe'(u_rec) f0], the second-order terms (c k)² under rounding; filters instead of
        # a Newton per sample, which made every score step of a lumped model crawl
        f0 = qlv(t, phi * elastic_force(kind, p, u_rec), g, tau)
        if isinstance(c, (int, float)) and c == 0:
            return u_rec * 1.0, f0
        return u_rec - c * f0, f0 - c * qlv(t, slope * f0, g, tau)
    if not len(g):
        u = u_rec * 1.0
        for _ in range(_NEWTON_MAX):
            k = 1 + c * phi * elastic_slope(kind, p, u)
            if np.any(np.real(k) <= 0):
                raise ForwardError(entry, "the series compliance and the element admit no unique tip "
                                   "position")
            du = (u + c * phi * elastic_force(kind, p, u) - u_rec) / k
            u = u - du
            if np.max(np.abs(np.real(du))) <= 1e-14 * scale:
                # one more step: the imaginary (derivative) part converges with the real part
                k = 1 + c * phi * elastic_slope(kind, p, u)
                u = u - (u + c * phi * elastic_force(kind, p, u) - u_rec) / k
                return u, phi * elastic_force(kind, p, u)
        raise ForwardError(entry, f"Newton did not converge in {_NEWTON_MAX} iterations")
    ginf = 1 - sum(g)
    dt = np.diff(t)
    fac = [_step_factors(dt, ti) for ti in tau]
    dtype = np.result_type(u_rec, phi, c, *g, *tau, *p.values(), float)
    u = np.zeros(len(t), dtype=dtype)
    f = np.zeros(len(t), dtype=dtype)
    fe_prev = 0 * u_rec[0]
    h = [0 * u_rec[0]] * len(g)
    for n in range(len(t)):
        if n == 0:      # relaxed under the first sample: f = g∞ φ Fe
            a, b = 0 * u_rec[0], ginf
        else:
            a = sum(g[i] * (fac[i][0][n - 1] * h[i] - fac[i][1][n - 1] * fe_prev) for i in range(len(g)))
            b = ginf + sum(g[i] * fac[i][1][n - 1] for i in range(len(g)))
        ph = phi[n]

        def r(v: Any, a: Any = a, b: Any = b, ph: Any = ph, n: int = n) -> Any:
            return v + c * (a + b * ph * elastic_force(kind, p, v)) - u_rec[n]

        def dr(v: Any, b: Any = b, ph: Any = ph) -> Any:
            return 1 + c * b * ph * elastic_slope(kind, p, v)

        u[n] = _newton_scalar(r, dr, u_rec[n], scale, entry)
        fe = ph * elastic_force(kind, p, u[n])
        f[n] = a + b * fe
        if n > 0:
            h = [fac[i][0][n - 1] * h[i] + fac[i][1][n - 1] * (fe - fe_prev) for i in range(len(g))]
        fe_prev = fe
    return u, f


# -- preconditioning --------------------------------------------------------------------------
def running_extreme(u: np.ndarray, previous: Any = 0.0) -> np.ndarray:
    """m(t) ``(T,)``: the largest |u| so far, starting from ``previous`` (complex-safe: the
    sample is chosen on real parts, its value, sign corrected, carries the derivative)."""
    a = np.abs(np.real(u))
    signed = u * np.where(np.real(u) < 0, -1.0, 1.0)
    idx = np.maximum.accumulate(np.where(a >= np.maximum.accumulate(a), np.arange(a.size), 0))
    m = signed[idx]
    return np.where(np.real(m) > np.real(previous), m, previous + 0 * m)


def softening_levels(drives: Sequence[np.ndarray]) -> list[np.ndarray]:
    """m(t)/m_ref per protocol (``drives`` in session order), each ``(T,)``; zeros without motion."""
    out, prev = [], 0.0
    ms = []
    for u in drives:
        m = running_extreme(u, prev)
        ms.append(m)
        prev = m[-1]
    ref = prev
    for m in ms:
        out.append(m / ref if np.real(ref) > 0 else 0 * m)
    return out


def running_strokes(u: np.ndarray, previous: Any = 0.0) -> np.ndarray:
    """S(t) ``(T,)``: ``previous`` plus the sum of the increases of |u| up to t, |u| counted from
    0 before the first sample (a protocol starts from the unloaded skin). Complex-safe: the
    sign and which steps are increases are chosen on real parts; the values carry the
    derivative."""
    a = u * np.where(np.real(u) < 0, -1.0, 1.0)
    steps = np.diff(a, prepend=0 * a[:1])
    return previous + np.cumsum(np.where(np.real(steps) > 0, steps, 0 * steps))


def stroke_levels(drives: Sequence[np.ndarray]) -> list[np.ndarray]:
    """A(t) per protocol (``drives`` in session order), each ``(T,)``: the strokes so far over
    the session's largest |drive| (one ramp from 0 to it adds 1); zeros without motion."""
    strokes, prev, ref = [], 0.0, 0.0
    for u in drives:
        s = running_strokes(u, prev)
        strokes.append(s)
        prev = s[-1]
        ref = running_extreme(u, ref)[-1]
    return [s / ref if np.real(ref) > 0 else 0 * s for s in strokes]


def softening_factors(form: str, drives: Sequence[np.ndarray], softening: Any, cycles: Any = 1.0
                      ) -> list[np.ndarray]:
    """φ(t) per protocol (``drives`` in session order), each ``(T,)`` [1]: ``form``
    ``"cycles"`` 1 − softening (1 − exp(−A/cycles)), ``"largest-load"`` 1 − softening m/m_ref.
    Exactly 1 at softening = 0."""
    if form == "cycles":
        return [1 - softening * (1 - np.exp(-a / cycles)) for a in stroke_levels(drives)]
    return [1 - softening * lev for lev in softening_levels(drives)]


__all__ = ["ELASTIC_PARAMETERS", "elastic_force", "elastic_inverse", "elastic_slope", "poly_names", "qlv",
           "qlv_inverse", "running_extreme", "running_strokes", "series_solve", "softening_factors",
           "softening_levels", "stroke_levels"]
