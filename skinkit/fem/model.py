"""The TOML model format: geometry, layers (law, parameters, pre-stress), boundary
conditions, indenter, load programme, solver options. See ``docs/models/README.md``.

Quantities are numbers in SI units or strings ``"<number> <unit>"`` (``"1.5 mm"``,
``"20 kPa"``, ``"30 deg"``); a unit of the wrong dimension is an error naming the entry.
"""

from __future__ import annotations

import copy
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from skinkit import registry
from skinkit.errors import PluginError, UnitError
from skinkit.fem import lawkit
from skinkit.fem.bcs import BoundaryConditions, Rigid
from skinkit.fem.errors import ModelError
from skinkit.fem.mesh import FEMesh, block_mesh, disc_mesh
from skinkit.fem.problem import Material, Problem
from skinkit.fem.solver import SolverOptions
from skinkit.units import is_known, si_unit, to_si

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

TOP_KEYS = {"model", "geometry", "layers", "boundary", "indenter", "load", "solver", "output",
            # session-driven forward models (skinkit.forward) and candidate effects
            "effects", "fields", "bindings", "instrument", "surface", "drive", "session"}


def quantity(value: Any, unit: str, entry: str) -> float:
    """A scalar in SI ``unit`` from a number (already SI) or a ``"<number> <unit>"`` string."""
    if isinstance(value, bool):
        raise ModelError(entry, f"expected a quantity in {unit}, got {value!r}")
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, str):
        parts = value.strip().split(None, 1)
        try:
            x = float(parts[0])
        except (ValueError, IndexError):
            raise ModelError(entry, f"expected '<number> <unit>', got {value!r}") from None
        u = parts[1].strip() if len(parts) > 1 else unit
        if not is_known(u):
            raise ModelError(entry, f"unknown unit {u!r} in {value!r}")
        try:
            return float(to_si(x, u, unit, entry))
        except UnitError:
            raise ModelError(entry, f"inconsistent units: {u!r} is not a unit of {si_unit(unit)!r}") from None
    raise ModelError(entry, f"expected a quantity in {unit}, got {value!r}")


def vector(value: Any, unit: str, entry: str, n: int = 3) -> np.ndarray:
    """A length-``n`` vector of quantities."""
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise ModelError(entry, f"expected a list of {n} quantities, got {value!r}")
    return np.array([quantity(v, unit, f"{entry}[{i}]") for i, v in enumerate(value)])


def _get(d: Mapping[str, Any], key: str, entry: str, default: Any = ...):
    if key in d:
        return d[key]
    if default is ...:
        raise ModelError(f"{entry}.{key}" if entry else key, "is required")
    return default


def _check_keys(d: Mapping[str, Any], allowed: set[str], entry: str) -> None:
    extra = sorted(set(d) - allowed)
    if extra:
        raise ModelError(entry, f"unknown key(s) {extra}; allowed are {sorted(allowed)}")


@dataclass
class LoadProgramme:
    """Times of the solution steps and the indenter programme ``value(t)`` (3,) [m or N]."""

    times: np.ndarray
    viscous_time: bool
    value: Any
    description: str


@dataclass
class Model:
    """A model ready to solve."""

    name: str
    spec: dict[str, Any]
    mesh: FEMesh
    problem: Problem
    bc: BoundaryConditions
    load: LoadProgramme
    options: SolverOptions
    intorder: int
    fixed_sets: list[str]
    points: np.ndarray | None = None
    point_depth: float = 0.0
    sensitivities: bool = False
    fields: list = None  # type: ignore[assignment]


def read_model(path: str | Path) -> dict[str, Any]:
    """Parse a TOML model file into a mapping (errors name the file)."""
    p = Path(path)
    if not p.is_file():
        raise ModelError(str(p), "no such model file")
    try:
        with p.open("rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise ModelError(str(p), f"not valid TOML: {exc}") from None


def load_model(path: str | Path) -> Model:
    """Read and build the model in ``path``."""
    spec = read_model(path)
    return build_model(spec)


def _law(layer: Mapping[str, Any], entry: str):
    name = _get(layer, "law", entry)
    opts = dict(layer.get("options", {}))
    try:
        return registry.create("skinkit.laws", name, **opts)
    except PluginError as exc:
        raise ModelError(f"{entry}.law", str(exc)) from None
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{entry}.options", f"law {name!r}: {exc}") from None


def _params(law: Any, given: Mapping[str, Any], entry: str) -> dict[str, float]:
    declared = {q.name: q for q in law.parameters()}
    unknown = sorted(set(given) - set(declared))
    if unknown:
        raise ModelError(f"{entry}.parameters", f"unknown parameter(s) {unknown} for law "
                         f"{law.name!r}; it has {sorted(declared)}")
    missing = sorted(set(declared) - set(given))
    if missing:
        raise ModelError(f"{entry}.parameters", f"missing parameter(s) {missing} for law {law.name!r} "
                         f"({lawkit.bounds_text(law)})")
    out = {n: quantity(given[n], declared[n].unit, f"{entry}.parameters.{n}") for n in declared}
    return lawkit.check_parameters(law, out, f"{entry}.parameters")


def _prestress(d: Mapping[str, Any] | None, entry: str):
    """``(F0, None)`` for a general initial deformation gradient, ``(None, (l1, l2, angle))``
    for an in-plane pre-stretch (whose stretches are then differentiable), or ``(None, None)``."""
    if not d:
        return None, None
    _check_keys(d, {"stretch", "angle", "F0"}, entry)
    if "F0" in d:
        try:
            F0 = np.asarray(d["F0"], dtype=float)
        except (TypeError, ValueError):
            raise ModelError(f"{entry}.F0", "must be a 3x3 matrix of numbers") from None
        if F0.shape != (3, 3) or np.linalg.det(F0) <= 0:
            raise ModelError(f"{entry}.F0", "must be a 3x3 matrix with positive determinant")
        return F0, None
    st = _get(d, "stretch", entry)
    if not isinstance(st, list) or len(st) != 2:
        raise ModelError(f"{entry}.stretch", f"expected [l1, l2], got {st!r}")
    l1, l2 = float(st[0]), float(st[1])
    if l1 <= 0 or l2 <= 0:
        raise ModelError(f"{entry}.stretch", f"stretches must be positive, got {st!r}")
    ang = quantity(d.get("angle", 0.0), "rad", f"{entry}.angle")
    return None, (l1, l2, ang)


def _mesh(spec: Mapping[str, Any], layers: list[tuple[str, float, int]]) -> tuple[FEMesh, float | None]:
    g = dict(_get(spec, "geometry", ""))
    kind = g.get("kind", "disc")
    if kind == "disc":
        _check_keys(g, {"kind", "diameter", "indenter_diameter", "n_inner", "n_ring", "grading"}, "geometry")
        mesh = disc_mesh(quantity(g.get("diameter", 0.040), "m", "geometry.diameter"),
                         quantity(g.get("indenter_diameter", 0.004), "m", "geometry.indenter_diameter"),
                         layers, int(g.get("n_inner", 3)), int(g.get("n_ring", 3)),
                         float(g.get("grading", 1.6)))
        return mesh, None
    if kind == "block":
        _check_keys(g, {"kind", "size", "n", "indenter_diameter"}, "geometry")
        size = vector(_get(g, "size", "geometry"), "m", "geometry.size", 2)
        n = g.get("n", [4, 4])
        H = sum(t for _, t, _ in layers)
        mesh = block_mesh((size[0], size[1], H), (int(n[0]), int(n[1]), 1), layers)
        d = g.get("indenter_diameter")
        if d is not None:
            r = 0.5 * quantity(d, "m", "geometry.indenter_diameter")
            x = mesh.nodes
            c = np.array([size[0] / 2, size[1] / 2])
            top = np.zeros(mesh.n_nodes, bool)
            top[mesh.node_sets["top"]] = True
            ind = top & (np.hypot(x[:, 0] - c[0], x[:, 1] - c[1]) <= r * (1 + 1e-9))
            if not ind.any():
                raise ModelError("geometry.indenter_diameter", "no top node lies under the indenter")
            mesh.node_sets["indenter"] = np.flatnonzero(ind)
        return mesh, None
    if kind == "twopad":
        from skinkit.fem.twopad import twopad_from_spec
        return twopad_from_spec(g, layers), None
    raise ModelError("geometry.kind", f"must be 'disc', 'block' or 'twopad', got {kind!r}")


def _load(spec: Mapping[str, Any], unit: str) -> LoadProgramme:
    d = dict(_get(spec, "load", ""))
    kind = d.get("kind", "ramp")
    if kind == "ramp":
        _check_keys(d, {"kind", "value", "steps", "duration"}, "load")
        v = vector(_get(d, "value", "load"), unit, "load.value")
        n = int(d.get("steps", 10))
        if n < 1:
            raise ModelError("load.steps", f"must be at least 1, got {n}")
        if "duration" in d:
            T = quantity(d["duration"], "s", "load.duration")
            return LoadProgramme(np.linspace(T / n, T, n), True, lambda t: min(t / T, 1.0) * v,
                                 f"ramp to {v} over {T} s")
        return LoadProgramme(np.linspace(1 / n, 1, n), False, lambda t: t * v, f"static ramp to {v}")
    if kind == "sinusoid":
        _check_keys(d, {"kind", "peak_to_peak", "frequency", "periods", "steps_per_period",
                        "direction"}, "load")
        pp = quantity(_get(d, "peak_to_peak", "load"), unit, "load.peak_to_peak")
        f = quantity(_get(d, "frequency", "load"), "Hz", "load.frequency")
        if f <= 0:
            raise ModelError("load.frequency", f"must be positive, got {f}")
        periods = float(d.get("periods", 3))
        spp = int(d.get("steps_per_period", 20))
        direc = np.asarray(d.get("direction", [0.0, 0.0, -1.0]), dtype=float)
        if direc.shape != (3,) or np.linalg.norm(direc) == 0:
            raise ModelError("load.direction", f"expected a non-zero 3-vector, got {d.get('direction')!r}")
        direc = direc / np.linalg.norm(direc)
        n = max(1, int(round(periods * spp)))
        T = periods / f
        return LoadProgramme(np.linspace(T / n, T, n), True,
                             lambda t: 0.5 * pp * (1 - math.cos(2 * math.pi * f * t)) * direc,
                             f"sinusoid {pp} peak to peak at {f} Hz, {periods} periods")
    if kind == "table":
        _check_keys(d, {"kind", "times", "values", "viscous"}, "load")
        t = np.array([quantity(x, "s", f"load.times[{i}]") for i, x in enumerate(_get(d, "times", "load"))])
        vals = _get(d, "values", "load")
        if len(vals) != t.size or t.size < 1 or np.any(np.diff(t) <= 0) or t[0] <= 0:
            raise ModelError("load", "times must be positive, increasing, one per value")
        V = np.array([vector(v, unit, f"load.values[{i}]") for i, v in enumerate(vals)])
        tt = np.concatenate([[0.0], t])
        VV = np.vstack([np.zeros(3), V])
        return LoadProgramme(t, bool(d.get("viscous", True)),
                             lambda x: np.array([np.interp(x, tt, VV[:, c]) for c in range(3)]),
                             f"table of {t.size} values")
    raise ModelError("load.kind", f"must be 'ramp', 'sinusoid' or 'table', got {kind!r}")


def build_model(spec: Mapping[str, Any], require_load: bool = True, mesh: FEMesh | None = None) -> Model:
    """Validate a parsed model description and build mesh, problem, BCs and programme.

    ``require_load``: False for a model driven by a session (the ``[load]`` table, if any, is
    then only a default programme). ``mesh``: use this mesh (e.g. fitted to a measured surface)
    instead of building the geometry's.
    """
    spec = copy.deepcopy(dict(spec))
    _check_keys(spec, TOP_KEYS, "model file")
    name = str(spec.get("model", {}).get("name", "model"))
    layers_spec = _get(spec, "layers", "")
    if not isinstance(layers_spec, list) or not layers_spec:
        raise ModelError("layers", "needs at least one [[layers]] table")
    layers, mats = [], []
    for i, L in enumerate(layers_spec):
        entry = f"layers[{i}]"
        _check_keys(L, {"name", "thickness", "elements", "law", "options", "parameters", "prestress"}, entry)
        lname = str(_get(L, "name", entry))
        th = quantity(_get(L, "thickness", entry), "m", f"{entry}.thickness")
        if th <= 0:
            raise ModelError(f"{entry}.thickness", f"must be positive, got {th}")
        layers.append((lname, th, int(L.get("elements", 2))))
        law = _law(L, entry)
        F0, pre = _prestress(L.get("prestress"), f"{entry}.prestress")
        mats.append(Material(lname, law, _params(law, dict(L.get("parameters", {})), entry),
                             F0=F0, prestress=pre))
    if len({n for n, _, _ in layers}) != len(layers):
        raise ModelError("layers", "layer names must be unique")
    if mesh is None:
        mesh, _ = _mesh(spec, layers)
    from skinkit.fem.fields import read_fields
    fields = read_fields(spec.get("fields"), [n for n, _, _ in layers], quantity)
    sol = dict(spec.get("solver", {}))
    _check_keys(sol, {"linear", "rtol", "atol", "max_iter", "max_cuts", "line_search", "intorder"}, "solver")
    intorder = int(sol.pop("intorder", 4))
    try:
        options = SolverOptions(**sol)
    except TypeError as exc:
        raise ModelError("solver", str(exc)) from None
    problem = Problem(mesh, mats, intorder=intorder, fields=fields)
    bd = dict(spec.get("boundary", {}))
    _check_keys(bd, {"fixed", "compliance"}, "boundary")
    fixed = list(bd.get("fixed", ["outer", "bottom"] if "outer" in mesh.node_sets else ["bottom"]))
    bc = BoundaryConditions(mesh.n_dof)
    fixed = _elastic_supports(bd.get("compliance"), mesh, fixed, bc)
    for s in fixed:
        if s not in mesh.node_sets:
            raise ModelError("boundary.fixed", f"no node set {s!r}; sets are {sorted(mesh.node_sets)}")
        bc.fix(mesh.node_sets[s])
    ind = spec.get("indenter")
    unit = "m"
    if ind is not None:
        _check_keys(ind, {"mode", "components"}, "indenter")
        mode = ind.get("mode", "displacement")
        unit = "N" if mode == "force" else "m"
        if "indenter" not in mesh.node_sets:
            raise ModelError("indenter", "the geometry has no indenter region (set indenter_diameter)")
        nodes = mesh.node_sets["indenter"]
        fixed_nodes = np.concatenate([mesh.node_sets[s] for s in fixed]) if fixed else np.zeros(0, int)
        nodes = np.setdiff1d(nodes, fixed_nodes)
        load = _load(spec, unit) if (require_load or "load" in spec) else _no_load()
        bc.rigid = Rigid(nodes, mode, load.value, tuple(ind.get("components", (0, 1, 2))))
    else:
        load = _load(spec, unit) if (require_load or "load" in spec) else _no_load()
    outp = dict(spec.get("output", {}))
    _check_keys(outp, {"points", "point_depth", "sensitivities"}, "output")
    points = None
    if "points" in outp:
        raw = outp["points"]
        if not isinstance(raw, list) or not raw:
            raise ModelError("output.points", "expected a list of [x, y, z] points")
        points = np.array([vector(p, "m", f"output.points[{i}]") for i, p in enumerate(raw)])
    depth = quantity(outp.get("point_depth", 0.0), "m", "output.point_depth")
    return Model(name, spec, mesh, problem, bc, load, options, intorder, fixed, points, depth,
                 bool(outp.get("sensitivities", False)), fields)


def _elastic_supports(d: Any, mesh: FEMesh, fixed: list[str], bc: BoundaryConditions) -> list[str]:
    """``[boundary] compliance = { sets = [...], value = c }``: the named sets (otherwise fixed)
    are held by a distributed elastic support, traction = -u / c with c [m/Pa]; c = 0 keeps
    them fixed, exactly. Returns the sets still fixed."""
    if d is None:
        return fixed
    if not isinstance(d, Mapping):
        raise ModelError("boundary.compliance", "must be a table { sets = [...], value = ... }")
    _check_keys(d, {"sets", "value"}, "boundary.compliance")
    sets = d.get("sets", [])
    if isinstance(sets, str):
        sets = [sets]
    for s in sets:
        if s not in mesh.node_sets:
            raise ModelError("boundary.compliance.sets",
                             f"no node set {s!r}; sets are {sorted(mesh.node_sets)}")
    c = quantity(_get(d, "value", "boundary.compliance"), "m/Pa", "boundary.compliance.value")
    if c < 0 or not math.isfinite(c):
        raise ModelError("boundary.compliance.value", f"must be zero or positive, got {c}")
    if c == 0:
        return fixed
    for s in sets:
        area = nodal_areas(mesh, mesh.node_sets[s])
        nodes = mesh.node_sets[s]
        bc.support(nodes, area[nodes] / c)
    return [s for s in fixed if s not in sets]


def nodal_areas(mesh: FEMesh, nodes: np.ndarray) -> np.ndarray:
    """``(N,)`` ∫ Nₐ dA over the boundary faces whose nodes all lie in ``nodes`` [m²]."""
    from skfem import ElementHex2, FacetBasis, LinearForm, asm

    m2 = mesh.skfem_mesh()
    inset = np.zeros(mesh.n_nodes, bool)
    inset[nodes] = True
    bf = m2.boundary_facets()
    facets = bf[np.all(inset[m2.facets[:, bf]], axis=0)]
    if facets.size == 0:
        raise ModelError("boundary.compliance.sets", "the set has no boundary face to support")
    fb = FacetBasis(m2, ElementHex2(), facets=facets, intorder=4)
    return asm(LinearForm(lambda v, w: v), fb)


def _no_load() -> LoadProgramme:
    """The placeholder programme of a session-driven model (the session gives the drive)."""
    return LoadProgramme(np.array([1.0]), False, lambda t: np.zeros(3), "driven by the session")


def layer_table(spec: Mapping[str, Any]) -> list[tuple[str, float, int]]:
    """``(name, thickness [m], element layers)`` of every ``[[layers]]`` table, top down."""
    out = []
    for i, L in enumerate(_get(spec, "layers", "")):
        out.append((str(_get(L, "name", f"layers[{i}]")),
                    quantity(_get(L, "thickness", f"layers[{i}]"), "m", f"layers[{i}].thickness"),
                    int(L.get("elements", 2))))
    return out


def build_mesh(spec: Mapping[str, Any]) -> FEMesh:
    """The mesh of a model description (before any surface fitting)."""
    return _mesh(spec, layer_table(spec))[0]
