"""Errors of the finite-element engine (all :class:`skinkit.errors.SkinkitError`)."""

from __future__ import annotations

from skinkit.errors import SkinkitError


class ModelError(SkinkitError):
    """A model description (file, law, parameter, boundary condition) is invalid.

    ``entry`` names the offending entry (``"layers[0].law"``).
    """

    def __init__(self, entry: str, problem: str) -> None:
        self.entry = entry
        self.problem = problem
        super().__init__(f"{entry}: {problem}")


class InvertedElementError(SkinkitError):
    """A deformation made ``det F <= 0`` at a quadrature point (an element turned inside out)."""

    def __init__(self, element: int, detF: float) -> None:
        self.element = int(element)
        self.detF = float(detF)
        super().__init__(f"element {element} is inverted (det F = {detF:.3g})")


class SolverError(SkinkitError):
    """Newton's method failed even after the load step was cut to its minimum."""
