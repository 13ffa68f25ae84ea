"""Kinematics of the three-axis parallel microrobot.

Mechanism (thesis 2.6.1, Figures 2-10 and 2-11; the kinematics appendix of Flynn et al.
2011 is not in the reference, so this model is derived here):

* three vertical linear actuators ("motor arms") stand at 120 deg on a circle of radius
  ``base_radius_m`` around the robot's z axis, at azimuths ``motor_angles_deg``;
* each arm carries a vee-jewel bearing at its top; a hardened pin sits in it and acts as a
  spherical joint at ``A_i = (r cos a_i, r sin a_i, q_i)``, ``q_i`` the arm position;
* the pin is held by a sliding block on a linear guide of the moving platform; the guides
  are radial lines of the platform through its centre ``P`` at the same azimuths, so the
  platform line ``P + s R u_i`` must pass through ``A_i`` (two scalar constraints per arm);
* the probe tip sits ``tip_height_m`` above ``P`` along the platform normal.

Six constraints fix the platform's six pose coordinates for any arm positions ``q``:
equal ``q`` lift the platform (normal indentation); raising one arm tilts the platform
about an axis perpendicular to that arm, which swings the tip sideways away from it by
about ``h dq / (1.5 r)`` (the "approximately tangential" single-motor extension of
thesis 4.1.3) while lifting it by ``dq / 3``.

Assumptions: rigid links, no backlash, the platform mass lumped into the arms, guides and
pins exactly in the platform plane. Coordinates: robot frame, z up along the normal
indentation, origin on the axis at the height where ``q = 0``. SI units throughout.

Solving is by batched Newton iteration on the 6 constraint residuals (forward) or on
6 residuals in the 3 rotation + 3 arm unknowns (inverse), both in closed-form residuals
with finite-difference Jacobians; converged residuals are below 1e-13 m.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from skinkit.errors import SkinkitError


class KinematicsError(SkinkitError):
    """A pose outside the mechanism's reach, or a solver that did not converge."""


@dataclass(frozen=True)
class Geometry:
    """Geometry of the mechanism (defaults: a compact build like the thesis robot).

    Attributes:
        base_radius_m: horizontal distance from the robot axis to each arm's pin [m].
        tip_height_m: probe tip above the platform centre along its normal [m].
        motor_angles_deg: azimuths of arms 1, 2, 3 [deg] (120 deg apart).
        travel_m: ``(min, max)`` arm position range [m] (mechanical stroke).
        home_m: arm position of the home pose, mid-stroke [m].
    """

    base_radius_m: float = 0.025
    tip_height_m: float = 0.030
    motor_angles_deg: tuple[float, float, float] = (90.0, 210.0, 330.0)
    travel_m: tuple[float, float] = (0.0, 0.010)
    home_m: float = 0.005
    _u: np.ndarray = field(init=False, repr=False, compare=False)
    _w: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.base_radius_m > 0 or not self.tip_height_m > 0:
            raise KinematicsError("Geometry: base_radius_m and tip_height_m must be > 0")
        lo, hi = self.travel_m
        if not lo < self.home_m < hi:
            raise KinematicsError(f"Geometry: home_m={self.home_m} is not inside travel_m={self.travel_m}")
        a = np.deg2rad(np.asarray(self.motor_angles_deg, dtype=float))
        u = np.stack([np.cos(a), np.sin(a), np.zeros(3)], axis=1)
        object.__setattr__(self, "_u", u)
        # in-plane normals of the guide lines (e_z x u), computed once: this is a hot path
        object.__setattr__(self, "_w", np.stack([-u[:, 1], u[:, 0], np.zeros(3)], axis=1))

    @property
    def radial(self) -> np.ndarray:
        """``(3, 3)`` unit radial directions of the arms (rows) in the platform frame."""
        return self._u

    @property
    def guide_normals(self) -> np.ndarray:
        """``(3, 3)`` unit in-plane normals ``e_z x radial`` of the arms' guide lines (rows)."""
        return self._w

    def pins_xy(self) -> np.ndarray:
        """``(3, 2)`` horizontal pin positions [m]."""
        return self.base_radius_m * self._u[:, :2]


def _rotation(r: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` from rotation vectors ``(..., 3)`` (Rodrigues)."""
    theta = np.linalg.norm(r, axis=-1)[..., None, None]
    k = np.zeros(r.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2] = -r[..., 2], r[..., 1]
    k[..., 1, 0], k[..., 1, 2] = r[..., 2], -r[..., 0]
    k[..., 2, 0], k[..., 2, 1] = -r[..., 1], r[..., 0]
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    eye = np.broadcast_to(np.eye(3), k.shape)
    return eye + a * k + b * (k @ k)


def _leg_residual(g: Geometry, p: np.ndarray, rot: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(..., 6)`` distances [m] of each pin from its platform line (two components each)."""
    w = g.guide_normals
    xy = g.pins_xy()
    a = np.empty(q.shape[:-1] + (3, 3))
    a[..., :2] = xy
    a[..., 2] = q
    d = a - p[..., None, :]  # (..., arms, 3)
    n = rot[..., :, 2]  # (..., 3) platform normal
    wr = np.einsum("...ij,aj->...ai", rot, w)  # (..., arms, 3)
    e1 = np.einsum("...ai,...i->...a", d, n)
    e2 = np.einsum("...ai,...ai->...a", d, wr)
    return np.concatenate([e1, e2], axis=-1)


def _newton(fun, x0: np.ndarray, tol: float = 1e-14, max_iter: int = 30) -> np.ndarray:
    """Batched Newton on ``fun: (..., 6) -> (..., 6)`` with a central-difference Jacobian."""
    x = x0.copy()
    h = 1e-7
    eye = np.eye(6) * h
    for _ in range(max_iter):
        f = fun(x)
        if np.all(np.abs(f) < tol):
            return x
        jac = np.stack([(fun(x + eye[j]) - fun(x - eye[j])) / (2 * h) for j in range(6)], axis=-1)
        try:
            x = x - np.linalg.solve(jac, f[..., None])[..., 0]
        except np.linalg.LinAlgError:
            raise KinematicsError(
                "kinematics: singular constraint Jacobian (pose outside the workspace)"
            ) from None
    f = fun(x)
    if not np.all(np.abs(f) < 1e-10):
        raise KinematicsError(f"kinematics: solver did not converge (residual {np.max(np.abs(f)):.3g} m)")
    return x


def platform_pose(q: np.ndarray, geometry: Geometry | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Platform centre ``(..., 3)`` [m] and rotation ``(..., 3, 3)`` for arm positions
    ``q`` ``(..., 3)`` [m]."""
    g = geometry or Geometry()
    q = np.asarray(q, dtype=float)
    x0 = np.zeros(q.shape[:-1] + (6,))
    x0[..., 2] = q.mean(axis=-1)

    def fun(x: np.ndarray) -> np.ndarray:
        return _leg_residual(g, x[..., :3], _rotation(x[..., 3:]), q)

    x = _newton(fun, x0)
    return x[..., :3], _rotation(x[..., 3:])


def forward(q: np.ndarray, geometry: Geometry | None = None) -> np.ndarray:
    """Tip position ``(..., 3)`` [m] in the robot frame from arm positions ``q`` ``(..., 3)`` [m]."""
    g = geometry or Geometry()
    p, rot = platform_pose(q, g)
    return p + g.tip_height_m * rot[..., :, 2]


def inverse(tip: np.ndarray, geometry: Geometry | None = None) -> np.ndarray:
    """Arm positions ``(..., 3)`` [m] that put the tip at ``tip`` ``(..., 3)`` [m].

    Unknowns are the platform rotation and the arm positions; the platform centre follows
    from the tip. Raises :class:`KinematicsError` when no pose reaches ``tip``.
    """
    g = geometry or Geometry()
    tip = np.asarray(tip, dtype=float)
    if tip.shape[-1:] != (3,):
        raise KinematicsError(f"inverse kinematics: tip must have shape (..., 3), got {tip.shape}")
    h = g.tip_height_m
    x0 = np.zeros(tip.shape[:-1] + (6,))
    x0[..., 3:] = (tip[..., 2] - h)[..., None]

    def fun(x: np.ndarray) -> np.ndarray:
        rot = _rotation(x[..., :3])
        p = tip - h * rot[..., :, 2]
        return _leg_residual(g, p, rot, x[..., 3:])

    x = _newton(fun, x0)
    return x[..., 3:]


def jacobian(q: np.ndarray, geometry: Geometry | None = None, step_m: float = 1e-6) -> np.ndarray:
    """``(..., 3, 3)`` tip velocity per arm velocity ``d tip_i / d q_j`` [1] at ``q`` ``(..., 3)``.

    Central differences of :func:`forward`; the error is O(step^2 / r), below 1e-9.
    Motor forces that balance a tip force ``f`` are ``J.T @ f`` (virtual work).
    """
    return forward_and_jacobian(q, geometry, step_m)[1]


def forward_and_jacobian(
    q: np.ndarray, geometry: Geometry | None = None, step_m: float = 1e-6
) -> tuple[np.ndarray, np.ndarray]:
    """Tip ``(..., 3)`` [m] and Jacobian ``(..., 3, 3)`` in one batched solve (7 poses per ``q``)."""
    g = geometry or Geometry()
    q = np.asarray(q, dtype=float)
    steps = np.concatenate([np.zeros((1, 3)), step_m * np.eye(3), -step_m * np.eye(3)])
    tips = forward(q[..., None, :] + steps, g)  # (..., 7, 3)
    jac = (tips[..., 1:4, :] - tips[..., 4:7, :]) / (2 * step_m)  # (..., j, i)
    return tips[..., 0, :], np.swapaxes(jac, -1, -2)


def in_travel(q: np.ndarray, geometry: Geometry | None = None) -> np.ndarray:
    """``(...)`` bool: every arm of ``q`` ``(..., 3)`` within the travel range."""
    g = geometry or Geometry()
    lo, hi = g.travel_m
    q = np.asarray(q, dtype=float)
    return np.all((q >= lo) & (q <= hi), axis=-1)
