"""Law machinery for the finite-element engine, and the tensor and hyperelastic building blocks
a law is written with: the implementation behind :mod:`skinkit.plugin.laws`, the declared,
stable API law plugins import (this module and those it re-exports from,
:mod:`skinkit.fem.hyper` and :mod:`skinkit.fem.tensors`, are engine internals).

Law machinery: stress and tangent of any :class:`skinkit.interfaces.Law`, from its energy if need be.

Conventions (all batched over leading axes):

* ``C`` ``(..., 3, 3)`` right Cauchy-Green tensor [1];
* ``S = 2 ∂W/∂C`` ``(..., 3, 3)`` second Piola-Kirchhoff stress [Pa];
* ``CC = 2 ∂S/∂C = 4 ∂²W/∂C∂C`` ``(..., 3, 3, 3, 3)`` material tangent [Pa] with minor and
  major symmetries.

A law may give only ``energy``; then the stress is its derivative, taken by the complex step
when the law declares ``complex_safe = True`` (exact to rounding), otherwise by central
differences. A missing tangent is the derivative of the stress, by the complex step when the
law's own ``stress`` is complex safe, otherwise by central differences. Optional extras a law
may declare, all used only when present:

* ``complex_safe: bool`` — ``energy``/``stress`` accept complex ``C`` and complex parameters
  and are complex-analytic (no ``abs``, no branches on complex values);
* ``prony(p) -> (g, tau)`` — the law is quasi-linear viscoelastic (see :mod:`.viscoelastic`);
* ``inadmissible(p) -> list[(name, reason)]`` — the physical conditions on the parameters that
  bounds alone cannot express (a positive shear modulus from several terms, a non-zero
  exponent, Prony moduli summing below 1): one ``(parameter name, one-line reason)`` per
  violated condition, ``""`` as the name for a joint condition; empty when ``p`` is admissible.
  :func:`check_parameters` refuses a violation with an error naming the entry, and the
  conformance kit (:mod:`.conformance`) checks that what the law admits responds physically.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from skinkit.fem.errors import ModelError
from skinkit.fem.hyper import (
    VOLUMETRIC_KINDS,
    b2,
    b4,
    check_volumetric,
    iso_hessian,
    iso_I1,
    iso_I2,
    iso_I4,
    kinematics,
    volumetric_coefficients,
    volumetric_energy,
    volumetric_stress,
    volumetric_tangent,
)
from skinkit.fem.tensors import I3, VOIGT, det3, inv3, outer, sym_direction, sym_product, trace

#: complex-step size: the derivative is Im f(x + ih)/h, free of subtraction error
_CS_STEP = 1e-30
#: central-difference step in C [1]: truncation ~h² and rounding ~eps/h balance near 1e-5..1e-6
_FD_STEP = 1e-6


def is_complex_safe(law: Any) -> bool:
    """True when ``law`` declares its energy/stress complex-analytic."""
    return bool(getattr(law, "complex_safe", False))


def has_own(law: Any, name: str) -> bool:
    """True when ``law`` provides a callable ``name`` (``stress`` or ``tangent``)."""
    return callable(getattr(law, name, None))


def default_parameters(law: Any) -> dict[str, float]:
    """name -> SI default value of every declared parameter of ``law``."""
    return {q.name: q.value for q in law.parameters()}


def check_parameters(law: Any, p: Mapping[str, Any], where: str = "law") -> dict[str, Any]:
    """Validate ``p`` against the law's declared parameters; returns a complete mapping.

    Missing parameters take their defaults only when ``p`` is None; an unknown name, a
    missing name, a value outside its admissible bounds or a violation of the law's own
    conditions (:func:`inadmissible`) raise :class:`ModelError` naming the parameter.
    """
    declared = {q.name: q for q in law.parameters()}
    unknown = sorted(set(p) - set(declared))
    if unknown:
        raise ModelError(where, f"unknown parameter(s) {unknown} for law {law.name!r}; "
                         f"it has {sorted(declared)}")
    missing = sorted(set(declared) - set(p))
    if missing:
        raise ModelError(where, f"missing parameter(s) {missing} for law {law.name!r}")
    out: dict[str, Any] = {}
    for name, q in declared.items():
        v = p[name]
        try:
            arr = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            raise ModelError(f"{where}.{name}", f"expected a number in {q.unit}, got {v!r}") from None
        if not np.all(np.isfinite(arr)):
            raise ModelError(f"{where}.{name}", f"must be finite, got {v!r}")
        out[name] = v
    for name, q in declared.items():
        arr = np.asarray(out[name], dtype=float)
        if np.any(arr < q.lower) or np.any(arr > q.upper):
            # the law's own reason, when it has one for this parameter, says more than the range
            why = dict(inadmissible(law, out, where)).get(name)
            raise ModelError(f"{where}.{name}", f"value {_show(arr)} {q.unit} is outside its admissible "
                             f"range [{q.lower:g}, {q.upper:g}]" + (f": {why}" if why else ""))
    problems = inadmissible(law, out, where)
    if problems:
        name, why = problems[0]
        raise ModelError(f"{where}.{name}" if name else where, why)
    return out


def inadmissible(law: Any, p: Mapping[str, Any], where: str = "law") -> list[tuple[str, str]]:
    """The law's own physical conditions violated by ``p`` (``law.inadmissible(p)``, see the
    module docstring): ``[(parameter name or "", reason), ...]``, empty when admissible or when
    the law declares none. A law whose check itself fails is refused naming ``where``."""
    fn = getattr(law, "inadmissible", None)
    if not callable(fn):
        return []
    try:
        with np.errstate(all="ignore"):
            found = fn(p)
        out = [(str(n), str(why)) for n, why in (found or [])]
    except (ArithmeticError, LookupError, TypeError, ValueError) as exc:
        raise ModelError(where, f"law {getattr(law, 'name', law)!r} cannot check its parameters: "
                         f"{type(exc).__name__}: {exc}") from None
    return out


def require_positive(p: Mapping[str, Any], names: Sequence[str], what: str) -> list[tuple[str, str]]:
    """``[(name, reason)]`` for each of ``names`` whose value (any element of it) is not > 0;
    ``what`` says why it must be ("the small-strain shear modulus")."""
    out = []
    for n in names:
        v = np.real(np.asarray(p[n]))
        if np.any(~(v > 0)):
            out.append((n, f"must be positive ({what}), got {_show(v)}"))
    return out


def _show(v: Any) -> str:
    a = np.asarray(v)
    return f"{float(a):g}" if a.ndim == 0 else np.array2string(a, precision=4, threshold=6)


def _energy_gradient(law: Any, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    """S = 2 ∂W/∂C from the energy alone."""
    C = np.asarray(C)
    S = np.zeros(C.shape, dtype=float)
    cs = is_complex_safe(law)
    for K, L in VOIGT:
        E = sym_direction(K, L)
        if cs:
            d = np.imag(law.energy(C + 1j * _CS_STEP * E, p)) / _CS_STEP
        else:
            d = (np.asarray(law.energy(C + _FD_STEP * E, p))
                 - np.asarray(law.energy(C - _FD_STEP * E, p))) / (2 * _FD_STEP)
        S[..., K, L] = 2 * d
        S[..., L, K] = 2 * d
    return S


def stress(law: Any, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    """``(..., 3, 3)`` PK2 stress [Pa] of ``law`` at ``C``: its own, or derived from its energy."""
    if has_own(law, "stress"):
        return np.asarray(law.stress(C, p))
    return _energy_gradient(law, C, p)


def _stress_is_complex_safe(law: Any) -> bool:
    # the derived stress (an Im or a difference) is real: only a law's own stress can be stepped
    return has_own(law, "stress") and is_complex_safe(law)


#: second-difference step of the energy Hessian: truncation ~h² and rounding ~eps/h² meet
#: near 1e-4 (both about 1e-8 of the tangent)
_FD2_STEP = 1e-4


def energy_hessian(law: Any, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    """``(..., 3, 3, 3, 3)`` CC = 4 ∂²W/∂C∂C [Pa] by second central differences of the
    energy alone (``C`` ``(..., 3, 3)``), whatever stress or tangent the law has of its own:
    an independent reference for checking them."""
    C = np.asarray(C, dtype=float)
    CC = np.zeros(C.shape + (3, 3), dtype=float)
    h = _FD2_STEP
    dirs = [sym_direction(K, L) for K, L in VOIGT]
    for a, (I, J) in enumerate(VOIGT):
        for b in range(a, 6):
            K, L = VOIGT[b]
            Ea, Eb = dirs[a], dirs[b]
            d2 = (law.energy(C + h * Ea + h * Eb, p) - law.energy(C + h * Ea - h * Eb, p)
                  - law.energy(C - h * Ea + h * Eb, p) + law.energy(C - h * Ea - h * Eb, p)) / (4 * h * h)
            for (i, j) in {(I, J), (J, I)}:
                for (k, l) in {(K, L), (L, K)}:
                    CC[..., i, j, k, l] = 4 * d2
                    CC[..., k, l, i, j] = 4 * d2
    return CC


def tangent_from_stress(law: Any, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    """``(..., 3, 3, 3, 3)`` tangent 2 ∂S/∂C by differentiating :func:`stress`.

    For a law with only a real (not complex-safe) energy, the second differences of the
    energy are used instead: differencing a differenced stress would square the rounding.
    """
    if not has_own(law, "stress") and not is_complex_safe(law):
        return energy_hessian(law, C, p)
    C = np.asarray(C, dtype=float)
    CC = np.zeros(C.shape + (3, 3), dtype=float)
    cs = _stress_is_complex_safe(law)
    for K, L in VOIGT:
        E = sym_direction(K, L)
        if cs:
            dS = np.imag(law.stress(C + 1j * _CS_STEP * E, p)) / _CS_STEP
        else:
            dS = (stress(law, C + _FD_STEP * E, p) - stress(law, C - _FD_STEP * E, p)) / (2 * _FD_STEP)
        CC[..., :, :, K, L] = 2 * dS
        CC[..., :, :, L, K] = 2 * dS
    if not cs:
        # a hyperelastic tangent has major symmetry; differences break it at rounding level only
        CC = 0.5 * (CC + np.swapaxes(np.swapaxes(CC, -4, -2), -3, -1))
    return CC


def tangent(law: Any, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    """``(..., 3, 3, 3, 3)`` material tangent [Pa]: the law's own or derived."""
    if has_own(law, "tangent"):
        return np.asarray(law.tangent(C, p))
    return tangent_from_stress(law, C, p)


def response(law: Any, C: np.ndarray, p: Mapping[str, Any], with_tangent: bool = True):
    """``(S, CC)`` of ``law`` at ``C`` (``CC`` is None when ``with_tangent`` is False).

    A law may provide ``response(C, p, with_tangent)`` itself to share work between the two.
    """
    own = getattr(law, "response", None)
    if callable(own):
        return own(C, p, with_tangent)
    S = stress(law, C, p)
    return S, (tangent(law, C, p) if with_tangent else None)


def parameter_step(value: float) -> float:
    """Central-difference step for a parameter of magnitude ``value``."""
    return 1e-6 * max(abs(value), 1e-8)


def stress_parameter_derivative(law: Any, C: np.ndarray, p: Mapping[str, Any],
                                name: str) -> np.ndarray:
    """``∂S/∂p[name]`` ``(..., 3, 3)`` [Pa per parameter unit] at fixed ``C``.

    Complex step when the law's stress is complex safe, otherwise central differences.
    """
    v = p[name]
    if _stress_is_complex_safe(law):
        q = dict(p)
        q[name] = v + 1j * _CS_STEP
        return np.imag(law.stress(np.asarray(C, dtype=complex), q)) / _CS_STEP
    h = parameter_step(float(np.max(np.abs(v))))
    qp = dict(p)
    qm = dict(p)
    qp[name] = v + h
    qm[name] = v - h
    return (stress(law, C, qp) - stress(law, C, qm)) / (2 * h)


def parameter_names(law: Any) -> list[str]:
    """Declared parameter names of ``law``, in order."""
    return [q.name for q in law.parameters()]


def bounds_text(law: Any) -> str:
    """One line listing the law's parameters with units and bounds (for messages)."""
    parts = []
    for q in law.parameters():
        lo = "-inf" if math.isinf(q.lower) else f"{q.lower:g}"
        hi = "inf" if math.isinf(q.upper) else f"{q.upper:g}"
        parts.append(f"{q.name} [{q.unit}] in [{lo}, {hi}]")
    return "; ".join(parts)


def broadcast_param(v: Any, shape: Sequence[int]) -> Any:
    """A parameter value ready to broadcast against a batch of ``shape``."""
    a = np.asarray(v)
    return a if a.ndim == 0 else a.reshape(a.shape + (1,) * (len(shape) - a.ndim))


__all__ = [
    # law machinery
    "bounds_text",
    "broadcast_param",
    "check_parameters",
    "default_parameters",
    "energy_hessian",
    "has_own",
    "inadmissible",
    "is_complex_safe",
    "parameter_names",
    "parameter_step",
    "require_positive",
    "response",
    "stress",
    "stress_parameter_derivative",
    "tangent",
    "tangent_from_stress",
    # batched 3x3 tensor algebra (skinkit.fem.tensors)
    "I3",
    "VOIGT",
    "det3",
    "inv3",
    "outer",
    "sym_direction",
    "sym_product",
    "trace",
    # hyperelastic building blocks (skinkit.fem.hyper)
    "VOLUMETRIC_KINDS",
    "b2",
    "b4",
    "check_volumetric",
    "iso_I1",
    "iso_I2",
    "iso_I4",
    "iso_hessian",
    "kinematics",
    "volumetric_energy",
    "volumetric_stress",
    "volumetric_coefficients",
    "volumetric_tangent",
]
