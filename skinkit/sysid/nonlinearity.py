"""Static nonlinearities: thesis Eq. 4.9 exponential and polynomials, fitted by least squares."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from skinkit.sysid.checks import SysidError


@dataclass(frozen=True)
class StaticNonlinearity:
    """``kind="exponential"``: ``y0 + C1 (1 - exp(-C2 x))`` with ``params = (C1 [m], C2 [1/N],
    y0 [m])``; ``kind="polynomial"``: ``params`` are coefficients, highest power first."""

    kind: str
    params: tuple[float, ...]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The static nonlinearity at ``x`` (any shape), same shape."""
        x = np.asarray(x, float)
        if self.kind == "exponential":
            c1, c2, y0 = self.params
            return y0 + c1 * -np.expm1(-c2 * x)
        return np.polyval(self.params, x)

    def slope(self, x: np.ndarray) -> np.ndarray:
        """Derivative dy/dx at ``x`` (the local compliance of a Wiener model) [m/N]."""
        x = np.asarray(x, float)
        if self.kind == "exponential":
            c1, c2, _ = self.params
            return c1 * c2 * np.exp(-c2 * x)
        return np.polyval(np.polyder(self.params), x)

    def to_dict(self) -> dict[str, object]:
        """The kind and its parameters as a plain dict (with units in the keys)."""
        if self.kind == "exponential":
            c1, c2, y0 = self.params
            return {"kind": "exponential", "C1_m": c1, "C2_per_N": c2, "offset_m": y0}
        return {"kind": "polynomial", "coefficients": list(self.params)}


def fit_exponential(x: np.ndarray, y: np.ndarray, fit_offset: bool = False,
                    start: StaticNonlinearity | None = None) -> StaticNonlinearity:
    """Least-squares ``C1, C2`` (and offset) of ``y ~ y0 + C1 (1 - exp(-C2 x))``."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if start is not None and start.kind == "exponential":
        c1, c2, y0 = start.params
    else:
        # y ~ a x + b x^2 + y0 near x = 0 gives C1 C2 = a and -C1 C2^2 / 2 = b
        b, a, y0 = np.polyfit(x, y, 2)
        if a != 0 and b != 0:  # saturating (C2 > 0) or, for b * a > 0, stiffening-free growth
            c2 = -2 * b / a
        else:
            c2 = 1e-3 / max(float(np.max(np.abs(x))), 1e-12)
        c1 = a / c2
        if not fit_offset:
            y0 = 0.0
    p0 = [c1, c2, y0] if fit_offset else [c1, c2]

    def resid(p: np.ndarray) -> np.ndarray:
        off = p[2] if fit_offset else 0.0
        return off + p[0] * -np.expm1(-p[1] * x) - y

    scale = np.abs(np.asarray(p0, float)) + 1e-12
    sol = least_squares(resid, np.asarray(p0, float), method="lm", x_scale=scale)
    p = sol.x
    return StaticNonlinearity("exponential", (float(p[0]), float(p[1]),
                                              float(p[2]) if fit_offset else 0.0))


def fit_polynomial(x: np.ndarray, y: np.ndarray, degree: int = 3) -> StaticNonlinearity:
    """Least-squares polynomial of ``degree`` (with constant term)."""
    if degree < 1:
        raise SysidError(f"polynomial degree must be at least 1, got {degree}")
    return StaticNonlinearity("polynomial", tuple(float(c) for c in np.polyfit(x, y, degree)))
