"""Quasi-linear viscoelasticity: a Prony series around any elastic law (thesis Eqs 7.6-7.7).

S(t) = ∫₀ᵗ g_R(t - s) dSₑ/ds ds with g_R(t) = 1 - Σᵢ gᵢ (1 - exp(-t/τᵢ)), Sₑ the elastic
law's PK2 stress (the engine integrates it, see :mod:`skinkit.fem.viscoelastic`). In a
static solve the law answers with its instantaneous elastic response.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import Any

import numpy as np

from skinkit import registry
from skinkit.errors import SkinkitError
from skinkit.plugin import laws as lawkit
from skinkit.schemas import Parameter


def _elastic_law(name: str, options: Any) -> Any:
    """The elastic law ``name`` built with ``options``; ValueError (a law's refusal of an
    option) for an unknown law, options that are not a table or that its constructor lacks."""
    if options is not None and not isinstance(options, Mapping):
        raise ValueError(f"elastic_options must be a table, got {options!r}")
    try:
        cls = registry.load("skinkit.laws", name)
    except SkinkitError as exc:
        raise ValueError(f"elastic = {name!r}: {exc}") from None
    opts = dict(options or {})
    if isinstance(cls, type):
        try:  # checked against the signature, not by calling: a TypeError inside is a bug
            inspect.signature(cls).bind(**opts)
        except TypeError as exc:
            raise ValueError(f"elastic_options for {name!r}: {exc}") from None
        return cls(**opts)
    if opts:
        raise ValueError(f"elastic law {name!r} takes no options, got {sorted(opts)}")
    return cls


class QLV:
    """Options: ``elastic`` (a law name in ``skinkit.laws`` or a law object), ``terms`` (N ≥ 1),
    ``elastic_options`` (mapping passed to the elastic law). Parameters: the elastic law's,
    then ``g1..gN`` [1] (Σ gᵢ < 1) and ``tau1..tauN`` [s]."""

    name = "qlv"

    def __init__(self, elastic: Any = "neo-hookean-ni", terms: int = 1,
                 elastic_options: Mapping[str, Any] | None = None) -> None:
        if (isinstance(terms, bool) or not isinstance(terms, (int, float))
                or not float(terms).is_integer() or terms < 1):
            raise ValueError(f"terms must be a positive integer, got {terms!r}")
        self.terms = int(terms)
        if isinstance(elastic, str):
            elastic = _elastic_law(elastic, elastic_options)
        if not callable(getattr(elastic, "energy", None)):
            raise ValueError(f"elastic must be a law with an energy, got {elastic!r}")
        self.elastic = elastic

    @property
    def complex_safe(self) -> bool:  # type: ignore[override]
        """True when the elastic law is complex-step safe and has its own stress."""
        return lawkit.is_complex_safe(self.elastic) and lawkit.has_own(self.elastic, "stress")

    def parameters(self) -> list[Parameter]:
        """Declared parameters: the elastic law's, then ``g1..gN`` [1] and ``tau1..tauN`` [s]."""
        out = list(self.elastic.parameters())
        for i in range(1, self.terms + 1):
            out.append(Parameter(f"g{i}", 0.3 / self.terms, "1", 0.0, 0.999))
        for i in range(1, self.terms + 1):
            out.append(Parameter(f"tau{i}", 10.0 ** (i - 1), "s", 1e-6, 1e6))
        return out

    def inadmissible(self, p: Mapping[str, Any]) -> list[tuple[str, str]]:
        """The elastic law's conditions, and Σ gᵢ < 1: the relaxed modulus g∞ = 1 - Σ gᵢ of
        the reduced relaxation function must stay positive."""
        out = lawkit.inadmissible(self.elastic, self._elastic_p(p))
        g = sum(np.real(np.asarray(p[f"g{i}"])) for i in range(1, self.terms + 1))
        if np.any(~(g < 1.0)):
            names = " + ".join(f"g{i}" for i in range(1, self.terms + 1))
            out.append(("", f"the Prony moduli {names} = {np.max(g):g} must sum below 1 (the "
                            f"relaxed modulus g_inf = 1 - sum g must stay positive)"))
        return out

    def _elastic_p(self, p: Mapping[str, Any]) -> dict[str, Any]:
        names = lawkit.parameter_names(self.elastic)
        return {n: p[n] for n in names}

    def prony(self, p: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        """``(g, tau)`` each ``(N,)``: relative moduli [1] and relaxation times [s]."""
        g = np.array([p[f"g{i}"] for i in range(1, self.terms + 1)])
        tau = np.array([p[f"tau{i}"] for i in range(1, self.terms + 1)])
        if np.real(g).sum() >= 1.0:
            raise ValueError(f"the Prony moduli must sum below 1, got {np.real(g).sum():g}")
        return g, tau

    def energy(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Instantaneous (elastic) strain-energy density W (...) [Pa] of ``C`` (..., 3, 3)."""
        return self.elastic.energy(C, self._elastic_p(p))

    def stress(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Instantaneous (elastic) stress S (..., 3, 3) [Pa] of ``C`` (..., 3, 3)."""
        return lawkit.stress(self.elastic, C, self._elastic_p(p))

    def tangent(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Instantaneous (elastic) tangent 2 ∂S/∂C (..., 3, 3, 3, 3) [Pa] of ``C`` (..., 3, 3)."""
        return lawkit.tangent(self.elastic, C, self._elastic_p(p))

    def response(self, C: np.ndarray, p: Mapping[str, Any], with_tangent: bool = True):
        """``(S, CC)`` of the elastic law at ``C`` (``CC`` None without ``with_tangent``)."""
        return lawkit.response(self.elastic, C, self._elastic_p(p), with_tangent)
