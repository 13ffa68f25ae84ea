"""Lumped skin loads for the simulated robot.

A load maps the tip displacement ``u`` from the skin's rest point and the tip velocity ``v``
(robot frame, [m], [m/s]) to the force ``f`` [N] that the skin applies to the probe. Until
the probe first touches the skin only compression is possible; the thesis glues the probe
with cyanoacrylate at contact (7.2.1), so from first contact on the load is bilateral.
Loads are called once per control tick with plain floats, hence the tuple interface.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol


class SkinLoad(Protocol):
    """What the simulated robot needs from a skin model."""

    glued: bool

    def reaction(
        self, u: tuple[float, float, float], v: tuple[float, float, float], dt: float
    ) -> tuple[float, float, float]:
        """Force on the probe [N] for displacement ``u`` [m] and velocity ``v`` [m/s]."""


@dataclass
class KelvinVoigtSkin:
    """Spring and dashpot in parallel, stiffer normal than tangential.

    Defaults are of the order of the in vivo forearm stiffness of thesis chapter 4
    (3 kN/m: 10.5 N of summed motor force indents ~3.5 mm) [assumed values].
    """

    k_normal_N_per_m: float = 3000.0
    k_tangential_N_per_m: float = 1500.0
    b_normal_Ns_per_m: float = 3.0
    b_tangential_Ns_per_m: float = 1.5
    glued: bool = False

    def reaction(self, u, v, dt):  # noqa: ANN001 - hot path, plain floats
        """Force on the probe [N] for displacement ``u`` [m], velocity ``v`` [m/s]; none before contact."""
        if not self.glued:
            if u[2] <= 0.0:
                return (0.0, 0.0, 0.0)
            self.glued = True
        kt, kn, bt, bn = (
            self.k_tangential_N_per_m,
            self.k_normal_N_per_m,
            self.b_tangential_Ns_per_m,
            self.b_normal_Ns_per_m,
        )
        return (-(kt * u[0] + bt * v[0]), -(kt * u[1] + bt * v[1]), -(kn * u[2] + bn * v[2]))


@dataclass
class WienerSkin:
    """Wiener cascade (thesis 4.1.2): a linear dynamic block followed by a static nonlinearity.

    Linear block per axis: ``w = u + tau * du/dt`` (a first-order lead, i.e. viscous
    contribution); static nonlinearity: ``f = -(k1 w + k3 w^3)`` (strain stiffening).
    """

    k1_normal_N_per_m: float = 2000.0
    k3_normal_N_per_m3: float = 2.0e8
    k1_tangential_N_per_m: float = 1000.0
    k3_tangential_N_per_m3: float = 1.0e8
    tau_s: float = 0.005
    glued: bool = False
    _k: tuple = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._k = (
            (self.k1_tangential_N_per_m, self.k3_tangential_N_per_m3),
            (self.k1_tangential_N_per_m, self.k3_tangential_N_per_m3),
            (self.k1_normal_N_per_m, self.k3_normal_N_per_m3),
        )

    def reaction(self, u, v, dt):  # noqa: ANN001 - hot path, plain floats
        """Force on the probe [N] for displacement ``u`` [m] and velocity ``v`` [m/s] over step ``dt`` [s]."""
        if not self.glued:
            if u[2] <= 0.0:
                return (0.0, 0.0, 0.0)
            self.glued = True
        tau = self.tau_s
        out = []
        for (k1, k3), ui, vi in zip(self._k, u, v, strict=True):
            w = ui + tau * vi
            out.append(-(k1 * w + k3 * w * w * w))
        return (out[0], out[1], out[2])


@dataclass
class NoSkin:
    """Free air: no load (calibration runs without a specimen)."""

    glued: bool = False

    def reaction(self, u, v, dt):  # noqa: ANN001
        """No force: ``(0, 0, 0)`` [N]."""
        return (0.0, 0.0, 0.0)


@dataclass
class SpringLoad:
    """A calibration spring of known stiffness along one tip direction, no mass or damping
    (thesis 4.1.4), glued from the start."""

    k_N_per_m: float = 200.0
    axis: int = 2
    glued: bool = True

    def reaction(self, u, v, dt):  # noqa: ANN001
        """The spring's force [N] along its axis for displacement ``u`` [m]."""
        f = [0.0, 0.0, 0.0]
        f[self.axis] = -self.k_N_per_m * u[self.axis]
        return (f[0], f[1], f[2])


SKINS = {"kelvin-voigt": KelvinVoigtSkin, "wiener": WienerSkin, "none": NoSkin, "spring": SpringLoad}


def make_skin(name: str) -> SkinLoad:
    """A default-parameter skin load by name (``kelvin-voigt``, ``wiener``, ``none``, ``spring``)."""
    from skinkit.errors import SkinkitError

    try:
        return SKINS[name]()
    except KeyError:
        raise SkinkitError(f"unknown skin load {name!r}; known: {sorted(SKINS)}") from None
