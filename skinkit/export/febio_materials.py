"""skinkit laws as FEBio materials (FEBio spec 4.0), in FEBio's units (MPa for stresses).

Each built-in law maps to the FEBio material whose strain-energy function is the same, with
the parameters converted to FEBio's convention (``docs/reference/febio-export.md`` has the
table). A law, option or value without an exact FEBio counterpart raises
:class:`UnsupportedFeature` naming it: the export never writes an approximation silently.

Wrappers nest from the outside in: ``viscoelastic`` (a QLV law's Prony series) around
``prestrain elastic`` (the layer's initial deformation gradient F0) around the elastic law.
Both wrappers are FEBio's coupled ones, so an uncoupled law inside keeps its own bulk modulus
``k`` and pressure model and relaxes and pre-strains as a whole, as in skinkit (the Prony
series acts on the full elastic stress, F0 on the full deformation).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError

#: Pa -> MPa (FEBio's stress unit in the mm, N, s system)
PA_TO_MPA = 1e-6
#: largest number of Prony terms of FEBio's viscoelastic material (g1..g6, t1..t6)
MAX_PRONY_TERMS = 6
#: largest number of terms of FEBio's uncoupled Ogden material (c1..c6, m1..m6)
MAX_OGDEN_TERMS = 6
#: skinkit's volumetric energy (a law's ``volumetric`` option) -> FEBio's ``pressure_model``:
#: "default" is U = k/2 (ln J)², "Abaqus" is U = k/2 (J - 1)²
PRESSURE_MODEL = {"log": "default", "quadratic": "Abaqus"}


class UnsupportedFeature(SkinkitError):
    """A feature of a skinkit model with no exact FEBio counterpart; the message names it."""

    def __init__(self, feature: str, why: str) -> None:
        self.feature = feature
        super().__init__(f"FEBio export: {feature}: {why}")


def fmt(x: float) -> str:
    """A float as the shortest text that reads back to the same double."""
    return repr(float(x))


def add_param(el: ET.Element, name: str, value: float) -> ET.Element:
    """Append ``<name>value</name>`` to ``el``."""
    sub = ET.SubElement(el, name)
    sub.text = fmt(value)
    return sub


def _pressure_model(law: Any, entry: str) -> str:
    kind = str(getattr(law, "volumetric", "log"))
    if kind not in PRESSURE_MODEL:
        raise UnsupportedFeature(f"{entry} volumetric = {kind!r}", "FEBio's pressure models are "
                                 "k/2 (ln J)^2 and k/2 (J-1)^2 only")
    return PRESSURE_MODEL[kind]


def _uncoupled(tag: str, ftype: str, law: Any, K: float, entry: str) -> ET.Element:
    el = ET.Element(tag, type=ftype)
    add_param(el, "k", K * PA_TO_MPA)
    ET.SubElement(el, "pressure_model").text = _pressure_model(law, entry)
    return el


def neo_hookean_E_v(mu: float, lam: float) -> tuple[float, float]:
    """FEBio's ``neo-Hookean`` E [Pa] and v [1] from the Lamé moduli μ, λ [Pa]:
    E = μ (3λ + 2μ) / (λ + μ), v = λ / (2 (λ + μ))."""
    return mu * (3 * lam + 2 * mu) / (lam + mu), lam / (2 * (lam + mu))


def _goh(tag: str, law: Any, p: Mapping[str, float], entry: str,
         notes: list[str] | None = None) -> ET.Element:
    if int(getattr(law, "families", 2)) != 2:
        raise UnsupportedFeature(f"{entry} goh families = 1", "FEBio's Holzapfel-Gasser-Ogden "
                                 "material always has two fibre families at +-gamma")
    if getattr(law, "switch", "febio") != "febio":
        feature = f"{entry} goh switch = {law.switch!r}"
        why = ("FEBio's Holzapfel-Gasser-Ogden material activates a family where I4 > 1 "
               "(switch = 'febio'); the Macaulay bracket <E> has no FEBio counterpart")
        if notes is None:
            raise UnsupportedFeature(feature, why)
        # the same energy wherever both switches agree (a stretched family with E > 0): the
        # nearest FEBio material, said as such rather than refused
        notes.append(f"{feature}: exported with FEBio's switch (a family active where I4 > 1, "
                     "not where E > 0); the two differ where a family is stretched but E <= 0, "
                     "or shortened with E > 0")
    el = _uncoupled(tag, "Holzapfel-Gasser-Ogden", law, p["k"], entry)
    add_param(el, "c", p["c"] * PA_TO_MPA)
    add_param(el, "k1", p["k1"] * PA_TO_MPA)
    add_param(el, "k2", p["k2"])
    add_param(el, "kappa", p["kappa"])
    # two families at +-gamma: the sign of gamma only swaps them, and FEBio takes degrees
    add_param(el, "gamma", math.degrees(abs(p["gamma"])))
    th = float(getattr(law, "frame_angle", 0.0))
    axis = ET.SubElement(el, "mat_axis", type="vector")
    ET.SubElement(axis, "a").text = ",".join(fmt(v) for v in (math.cos(th), math.sin(th), 0.0))
    ET.SubElement(axis, "d").text = ",".join(fmt(v) for v in (-math.sin(th), math.cos(th), 0.0))
    return el


def _ogden(tag: str, law: Any, p: Mapping[str, float], entry: str) -> ET.Element:
    n = int(getattr(law, "terms", 1))
    if n > MAX_OGDEN_TERMS:
        raise UnsupportedFeature(f"{entry} ogden terms = {n}", f"FEBio's Ogden material has at most "
                                 f"{MAX_OGDEN_TERMS} terms")
    el = _uncoupled(tag, "Ogden", law, p["K"], entry)
    for i in range(1, n + 1):
        # skinkit 2 mu_i / alpha_i^2 (...) is FEBio's c_i / m_i^2 (...): c_i = 2 mu_i, m_i = alpha_i
        add_param(el, f"c{i}", 2 * p[f"mu{i}"] * PA_TO_MPA)
        add_param(el, f"m{i}", p[f"alpha{i}"])
    return el


def elastic_element(tag: str, law: Any, p: Mapping[str, float], entry: str,
                    notes: list[str] | None = None) -> ET.Element:
    """The FEBio element (tag ``tag``) of the elastic law ``law`` at SI parameters ``p``;
    ``entry`` names the layer in errors (``layers[0] (skin)``). ``notes``: where a feature has
    a near but not exact FEBio counterpart, it is exported and said here (None: refused)."""
    name = str(getattr(law, "name", type(law).__name__))
    if name == "neo-hookean":
        E, v = neo_hookean_E_v(p["mu"], p["lam"])
        el = ET.Element(tag, type="neo-Hookean")
        add_param(el, "E", E * PA_TO_MPA)
        add_param(el, "v", v)
        return el
    if name in ("neo-hookean-ni", "neo-hookean-enu"):
        if name == "neo-hookean-ni":
            mu, K = p["mu"], p["K"]
        else:
            mu, K = p["E"] / (2 * (1 + p["nu"])), p["E"] / (3 * (1 - 2 * p["nu"]))
        # the uncoupled neo-Hookean is FEBio's uncoupled Mooney-Rivlin with c1 = mu/2, c2 = 0
        el = _uncoupled(tag, "Mooney-Rivlin", law, K, entry)
        add_param(el, "c1", 0.5 * mu * PA_TO_MPA)
        add_param(el, "c2", 0.0)
        return el
    if name == "mooney-rivlin":
        el = _uncoupled(tag, "Mooney-Rivlin", law, p["K"], entry)
        add_param(el, "c1", p["c1"] * PA_TO_MPA)
        add_param(el, "c2", p["c2"] * PA_TO_MPA)
        return el
    if name == "ogden":
        return _ogden(tag, law, p, entry)
    if name == "goh":
        return _goh(tag, law, p, entry, notes)
    raise UnsupportedFeature(f"{entry} law {name!r}", "no FEBio material with the same energy is "
                             "known to the exporter (exported: neo-hookean, neo-hookean-ni, "
                             "neo-hookean-enu, mooney-rivlin, ogden, goh, and qlv around them)")


def _prestrain(inner: ET.Element, F0: np.ndarray, entry: str) -> ET.Element:
    F0 = np.asarray(F0, dtype=float)
    if F0.shape != (3, 3):
        raise UnsupportedFeature(f"{entry} prestress", "a pre-stretch varying over the elements has "
                                 "no export (a model file's is one 3x3 F0 per layer)")
    el = ET.Element("elastic", type="prestrain elastic")
    el.append(inner)
    ps = ET.SubElement(el, "prestrain", type="prestrain gradient")
    add_param(ps, "ramp", 1.0)      # the full F0 from the first step, as in skinkit
    ET.SubElement(ps, "F0").text = ",".join(fmt(v) for v in F0.ravel())   # row by row
    return el


def _viscoelastic(inner: ET.Element, g: np.ndarray, tau: np.ndarray, entry: str) -> ET.Element:
    if len(g) > MAX_PRONY_TERMS:
        raise UnsupportedFeature(f"{entry} qlv terms = {len(g)}", f"FEBio's viscoelastic material "
                                 f"has at most {MAX_PRONY_TERMS} Prony terms")
    el = ET.Element("elastic", type="viscoelastic")
    # skinkit S = g_inf Se + sum g_i h_i with g_inf = 1 - sum g_i is FEBio's g0 Se + sum g_i H_i
    add_param(el, "g0", 1.0 - float(np.sum(g)))
    for i, (gi, ti) in enumerate(zip(g, tau, strict=True), start=1):
        add_param(el, f"g{i}", gi)
        add_param(el, f"t{i}", ti)
    el.append(inner)
    return el


def material_element(mat: Any, mid: int, name: str, entry: str,
                     notes: list[str] | None = None) -> ET.Element:
    """The top-level ``<material id name type>`` of a :class:`skinkit.fem.problem.Material`:
    the elastic law, wrapped in ``prestrain elastic`` when the layer has an F0 and in
    ``viscoelastic`` when the law is QLV; ``notes`` as for :func:`elastic_element`."""
    law, p = mat.law, {k: float(np.real(v)) for k, v in dict(mat.params).items()}
    prony = None
    if getattr(law, "name", "") == "qlv":
        elastic = law.elastic
        if getattr(elastic, "name", "") == "qlv":
            raise UnsupportedFeature(f"{entry} qlv around qlv", "FEBio nests one viscoelastic wrapper")
        g, tau = law.prony(p)
        prony = (np.real(np.asarray(g, dtype=float)), np.asarray(tau, dtype=float))
        p = {q.name: p[q.name] for q in elastic.parameters()}
        law = elastic
    el = elastic_element("elastic", law, p, entry, notes)
    if mat.F0 is not None:
        el = _prestrain(el, mat.F0, entry)
    if prony is not None:
        el = _viscoelastic(el, prony[0], prony[1], entry)
    el.tag = "material"
    el.attrib = {"id": str(mid), "name": name, **el.attrib}
    return el
