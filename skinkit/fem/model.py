"""The TOML model format: geometry, layers (law, parameters, pre-stress), boundary
conditions, indenter, load programme, solver options. See ``docs/reference/model-files.md``.

Quantities are numbers in SI units or strings ``"<number> <unit>"`` (``"1.5 mm"``,
``"20 kPa"``, ``"30 deg"``); a unit of the wrong dimension is an error naming the entry.
"""

from __future__ import annotations

import copy
import difflib
import inspect
import math
import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from skinkit import registry
from skinkit.errors import PluginError
from skinkit.fem import lawkit
from skinkit.fem.bcs import BoundaryConditions, ComplianceSupport, Rigid
from skinkit.fem.errors import ModelError
from skinkit.fem.mesh import FEMesh, block_mesh, disc_mesh
from skinkit.fem.problem import Material, Problem
from skinkit.fem.solver import SolverOptions
from skinkit.fem.values import (  # noqa: F401  (re-exported: the model format's value readers)
    GRADING_RANGE,
    bounded,
    flag,
    integer,
    quantity,
    table,
    text,
    vector,
)
from skinkit.fem.values import grading as _grading

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

TOP_KEYS = {"model", "geometry", "layers", "boundary", "indenter", "load", "solver", "output",
            # session-driven forward models (skinkit.forward) and candidate effects
            "effects", "fields", "bindings", "instrument", "surface", "drive", "session",
            # a calibrated model's record of where its values came from (skinkit.inverse.calibrated)
            "calibration"}


def _get(d: Mapping[str, Any], key: str, entry: str, default: Any = ...):
    if key in d:
        return d[key]
    if default is ...:
        raise ModelError(f"{entry}.{key}" if entry else key, "is required")
    return default


def _check_keys(d: Any, allowed: set[str], entry: str) -> None:
    """Refuse a non-table and a key not in ``allowed``, naming the nearest valid key."""
    if not isinstance(d, Mapping):
        raise ModelError(entry, f"expected a table, got {d!r}")
    extra = sorted(set(d) - allowed, key=str)
    if extra:
        key = str(extra[0])
        near = difflib.get_close_matches(key, sorted(allowed), n=1, cutoff=0.6)
        hint = f" (did you mean {near[0]!r}?)" if near else ""
        where = key if entry == "model file" else f"{entry}.{key}"
        raise ModelError(where, f"unknown key{hint}; allowed are {sorted(allowed)}")


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
    #: ``[solver] discretisation_tolerance``: relative error allowed on the tip force
    #: (displacement control) or tip motion (force control); None: not controlled
    discretisation_tolerance: float | None = None
    #: ``[solver] point_tolerance`` [m]: position error allowed on tracked points; None: not controlled
    point_tolerance: float | None = None


def read_model(path: str | Path) -> dict[str, Any]:
    """Parse a TOML model file into a mapping (errors name the file)."""
    p = Path(path)
    if not p.is_file():
        raise ModelError(str(p), "no such model file")
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise ModelError(str(p), f"cannot read the model file ({exc.strerror})") from None
    try:
        body = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ModelError(str(p), f"not a UTF-8 text file (byte 0x{raw[exc.start]:02x} at offset "
                         f"{exc.start}); a model file is TOML, which is UTF-8") from None
    try:
        spec = tomllib.loads(body)
    except tomllib.TOMLDecodeError as exc:
        raise ModelError(str(p), f"not valid TOML: {exc}") from None
    if not spec:  # else refused later for its first missing table, without naming the file
        raise ModelError(str(p), "is empty (no TOML tables); a model file holds [model], "
                         "[[layers]] and the other tables of a model description")
    return spec


def load_model(path: str | Path) -> Model:
    """Read and build the model in ``path``."""
    spec = read_model(path)
    return build_model(spec)


def _law(layer: Mapping[str, Any], entry: str):
    name = text(_get(layer, "law", entry), f"{entry}.law")
    opts = table(layer.get("options", {}), f"{entry}.options")
    try:
        law = registry.load("skinkit.laws", name)
    except PluginError as exc:
        raise ModelError(f"{entry}.law", str(exc)) from None
    if not isinstance(law, type):
        return law
    try:  # an unknown or missing option: checked against the signature, not by calling
        inspect.signature(law).bind(**opts)
    except TypeError as exc:
        raise ModelError(f"{entry}.options", f"law {name!r}: {exc}") from None
    try:
        return law(**opts)
    except ValueError as exc:  # how a law refuses an option's value; any other error is a bug
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
    for n, v in out.items():
        if declared[n].unit == "Pa" and abs(v) > MAX_MODULUS_PA:
            raise ModelError(f"{entry}.parameters.{n}", f"magnitude {abs(v):g} Pa is outside the plausible "
                             f"range [0, {MAX_MODULUS_PA:g}] Pa (stiffer than diamond)")
    return lawkit.check_parameters(law, out, f"{entry}.parameters")


def _fit_bounds(law: Any, given: Any, params: Mapping[str, float], entry: str
                ) -> dict[str, tuple[float, float]]:
    """A layer's ``bounds`` table: parameter name -> ``[lower, upper]`` (quantities in the law's
    unit), the range a fit may give it, inside the law's admissible range and around the file's
    value. Returns name -> (lower, upper) [SI]."""
    if given is None:
        return {}
    declared = {q.name: q for q in law.parameters()}
    out = {}
    for n, pair in table(given, entry).items():
        where = f"{entry}.{n}"
        if n not in declared:
            raise ModelError(where, f"unknown parameter for law {law.name!r}; it has {sorted(declared)}")
        if not isinstance(pair, list) or len(pair) != 2:
            raise ModelError(where, f"expected [lower, upper], got {pair!r}")
        lo, hi = (quantity(v, declared[n].unit, where) for v in pair)
        q = declared[n]
        if not lo < hi:
            raise ModelError(where, f"lower {lo:g} is not below upper {hi:g}")
        if lo < q.lower or hi > q.upper:
            raise ModelError(where, f"[{lo:g}, {hi:g}] leaves the law's admissible range "
                             f"[{q.lower:g}, {q.upper:g}] {q.unit}")
        if not lo <= params[n] <= hi:
            raise ModelError(where, f"the layer's value {params[n]:g} {q.unit} lies outside [{lo:g}, {hi:g}]")
        out[n] = (float(lo), float(hi))
    return out


def _prestress(d: Mapping[str, Any] | None, entry: str):
    """``(F0, None)`` for a general initial deformation gradient, ``(None, (l1, l2, angle))``
    for an in-plane pre-stretch (whose stretches are then differentiable), or ``(None, None)``."""
    if d is None:
        return None, None
    _check_keys(d, {"stretch", "angle", "F0"}, entry)
    if not d:
        return None, None
    lo, hi = PRESTRETCH_RANGE
    if "F0" in d:
        try:
            F0 = np.asarray(d["F0"], dtype=float)
        except (TypeError, ValueError):
            raise ModelError(f"{entry}.F0", "must be a 3x3 matrix of numbers") from None
        if F0.shape != (3, 3) or not np.all(np.isfinite(F0)) or np.linalg.det(F0) <= 0:
            raise ModelError(f"{entry}.F0",
                             "must be a 3x3 matrix of finite numbers with positive determinant")
        sv = np.linalg.svd(F0, compute_uv=False)
        if sv.min() < lo or sv.max() > hi:
            raise ModelError(f"{entry}.F0", f"principal stretches {sv.min():.3g}..{sv.max():.3g} are outside "
                             f"the plausible range [{lo:g}, {hi:g}] for tissue")
        return F0, None
    st = _get(d, "stretch", entry)
    if not isinstance(st, list) or len(st) != 2:
        raise ModelError(f"{entry}.stretch", f"expected [l1, l2], got {st!r}")
    l1, l2 = (bounded(v, "1", f"{entry}.stretch[{i}]", lo, hi, lo_open=False) for i, v in enumerate(st))
    ang = quantity(d.get("angle", 0.0), "rad", f"{entry}.angle")
    return None, (l1, l2, ang)


#: largest magnitude of a law parameter in Pa (diamond's moduli are about 1e12 Pa; tissue
#: and gels are below 1e9 Pa): beyond it the stress overflows long before anything is learnt
MAX_MODULUS_PA = 1e12
#: accepted range of element counts per direction (geometry ``n_*``, ``n``, layer ``elements``)
MAX_ELEMENTS_PER_DIRECTION = 200
#: accepted range of lengths (diameters, sizes, thicknesses) [m]
LENGTH_RANGE = (0.0, 1.0)
#: accepted range of in-plane pre-stretches and principal stretches of ``F0`` (tissue)
PRESTRETCH_RANGE = (0.5, 2.0)
#: accepted ``[solver] intorder`` (quadrature degree; 4 = 3x3x3 Gauss points)
INTORDER_RANGE = (2, 12)
#: largest force an indenter may be asked to apply [N] (skin tests stay far below)
MAX_FORCE_N = 1000.0
#: default largest number of unknowns a model may have (override: ``[solver] max_unknowns``
#: or the environment variable ``SKINKIT_MAX_UNKNOWNS``)
MAX_UNKNOWNS = 300_000
#: stored non-zeros per unknown of the 27-node hexahedral stiffness matrix (about 4^3 coupled
#: nodes x 3 components each) and bytes per non-zero (value + column index)
_NNZ_PER_UNKNOWN, _BYTES_PER_NNZ = 192, 12


def _geometry(spec: Mapping[str, Any]) -> dict[str, Any]:
    g = table(_get(spec, "geometry", ""), "geometry")
    kind = g.get("kind", "disc")
    if kind not in ("disc", "block", "twopad"):
        raise ModelError("geometry.kind", f"must be 'disc', 'block' or 'twopad', got {kind!r}")
    return g


def _count(g: Mapping[str, Any], key: str, default: int) -> int:
    return integer(g.get(key, default), f"geometry.{key}", 1, MAX_ELEMENTS_PER_DIRECTION)


def _block_n(g: Mapping[str, Any]) -> tuple[int, int]:
    n = g.get("n", [4, 4])
    if not isinstance(n, list) or len(n) != 2:
        raise ModelError("geometry.n", f"expected [nx, ny] element counts, got {n!r}")
    return tuple(integer(v, f"geometry.n[{i}]", 1, MAX_ELEMENTS_PER_DIRECTION) for i, v in enumerate(n))


def _fits_indenter(g: Mapping[str, Any]) -> bool:
    """Whether a block's elements are fitted to its indenter (``fit_indenter = true``)."""
    return flag(g.get("fit_indenter", False), "geometry.fit_indenter")


def estimate_size(spec: Mapping[str, Any], layers: list[tuple[str, float, int]]) -> dict[str, float]:
    """Elements, nodes, unknowns and stiffness-matrix memory [bytes] of the model's mesh,
    counted from the geometry table without building it (27-node hexahedra)."""
    g = _geometry(spec)
    nz = sum(k for _, _, k in layers)
    kind = g.get("kind", "disc")
    if kind == "disc" and flag(g.get("o_grid", False), "geometry.o_grid"):
        # the O-grid: the central block and n_ring rings of 4 n_inner elements each
        ni, nr = _count(g, "n_inner", 3), _count(g, "n_ring", 3)
        nodes = ((2 * ni + 1) ** 2 + 16 * ni * nr) * (2 * nz + 1)
        return {"elements": (ni * ni + 4 * ni * nr) * nz, "nodes": nodes, "unknowns": 3 * nodes,
                "matrix_bytes": 3.0 * nodes * _NNZ_PER_UNKNOWN * _BYTES_PER_NNZ}
    if kind == "disc":
        nx = ny = _count(g, "n_inner", 3) + 2 * _count(g, "n_ring", 3)
    elif kind == "block" and _fits_indenter(g):
        nx = ny = _count(g, "n_inner", 2) + 2 * _count(g, "n_ring", 2)
    elif kind == "block":
        nx, ny = _block_n(g)
    else:
        pad = _count(g, "n_pad", 2)
        nx = 2 * pad + _count(g, "n_gap", 6) + 2 * _count(g, "n_outer", 3)
        ny = pad + 2 * _count(g, "n_side", 3)
    nodes = (2 * nx + 1) * (2 * ny + 1) * (2 * nz + 1)
    unknowns = 3 * nodes
    return {"elements": nx * ny * nz, "nodes": nodes, "unknowns": unknowns,
            "matrix_bytes": float(unknowns) * _NNZ_PER_UNKNOWN * _BYTES_PER_NNZ}


def max_unknowns(spec: Mapping[str, Any] | None = None) -> int:
    """The size limit: ``[solver] max_unknowns``, else ``SKINKIT_MAX_UNKNOWNS``, else
    :data:`MAX_UNKNOWNS`."""
    sol = (spec or {}).get("solver", {})
    if isinstance(sol, Mapping) and "max_unknowns" in sol:
        return integer(sol["max_unknowns"], "solver.max_unknowns", 1, 10**12)
    env = os.environ.get("SKINKIT_MAX_UNKNOWNS")
    if env:
        try:
            return integer(int(env), "SKINKIT_MAX_UNKNOWNS", 1, 10**12)
        except ValueError:
            raise ModelError("SKINKIT_MAX_UNKNOWNS", f"expected a whole number, got {env!r}") from None
    return MAX_UNKNOWNS


def check_size(spec: Mapping[str, Any], layers: list[tuple[str, float, int]]) -> None:
    """Refuse a mesh larger than :func:`max_unknowns`, before it is built, with the estimate."""
    est = estimate_size(spec, layers)
    limit = max_unknowns(spec)
    if est["unknowns"] > limit:
        raise ModelError("geometry", f"the mesh would have {est['elements']:,} elements and "
                         f"{est['unknowns']:,} unknowns (stiffness matrix about "
                         f"{est['matrix_bytes'] / 1e9:.2g} GB before factorisation), over the limit of "
                         f"{limit:,}; coarsen the mesh, or raise the limit with [solver] max_unknowns "
                         "or SKINKIT_MAX_UNKNOWNS")


#: smallest element edge relative to the model's largest dimension: below it an element is
#: degenerate in double precision long before it is a useful refinement
MIN_EDGE_RATIO = 1e-6


def check_thinness(mesh: FEMesh) -> None:
    """Refuse a mesh with an element edge shorter than :data:`MIN_EDGE_RATIO` of the model's
    size (a length of the geometry or a layer far too small next to the others)."""
    corners = mesh.nodes[mesh.t.T]                                   # (E, 8, 3)
    d = np.linalg.norm(corners[:, :, None, :] - corners[:, None, :, :], axis=-1)
    d[:, np.arange(8), np.arange(8)] = np.inf
    edge = float(d.min())
    extent = float(np.ptp(mesh.nodes, axis=0).max())
    if not edge > MIN_EDGE_RATIO * extent:
        raise ModelError("geometry", f"the mesh has elements {edge:.3g} m thin in a model {extent:.3g} m "
                         f"across (less than {MIN_EDGE_RATIO:g} of it): a length of [geometry] or a layer "
                         "thickness is far too small next to the others")


def _mesh(spec: Mapping[str, Any], layers: list[tuple[str, float, int]]) -> tuple[FEMesh, float | None]:
    g = _geometry(spec)
    kind = g.get("kind", "disc")
    lo, hi = LENGTH_RANGE
    if kind == "disc":
        _check_keys(g, {"kind", "diameter", "indenter_diameter", "n_inner", "n_ring", "grading",
                        "inner_grading", "layer_grading", "o_grid"}, "geometry")
        D = bounded(g.get("diameter", 0.040), "m", "geometry.diameter", lo, hi)
        d = bounded(g.get("indenter_diameter", 0.004), "m", "geometry.indenter_diameter", lo, hi)
        if d >= D:
            raise ModelError("geometry.indenter_diameter", f"must be smaller than the disc's diameter "
                             f"{D:g} m, got {d:g} m")
        grading = _grading(g, "grading", 1.6)
        mesh = disc_mesh(D, d, layers, _count(g, "n_inner", 3), _count(g, "n_ring", 3), grading,
                         _grading(g, "inner_grading"), _grading(g, "layer_grading"),
                         flag(g.get("o_grid", False), "geometry.o_grid"))
        return mesh, None
    if kind == "block":
        fitted = _fits_indenter(g)
        _check_keys(g, {"kind", "size", "indenter_diameter", "layer_grading", "fit_indenter"}
                    | ({"n_inner", "n_ring", "grading", "inner_grading"} if fitted else {"n"}), "geometry")
        size = vector(_get(g, "size", "geometry"), "m", "geometry.size", 2)
        for i, v in enumerate(size):
            if not lo < v <= hi:
                raise ModelError(f"geometry.size[{i}]", f"must be in ({lo:g}, {hi:g}] m, got {v:g}")
        if fitted:
            if "indenter_diameter" not in g:
                raise ModelError("geometry.fit_indenter", "needs indenter_diameter (the circle to fit)")
            from skinkit.fem.mesh import fitted_block_mesh
            d = bounded(g["indenter_diameter"], "m", "geometry.indenter_diameter", 0.0, float(min(size)))
            return fitted_block_mesh(size, d, layers, _count(g, "n_inner", 2), _count(g, "n_ring", 2),
                                     _grading(g, "grading"), _grading(g, "inner_grading"),
                                     _grading(g, "layer_grading")), None
        n = _block_n(g)
        H = sum(t for _, t, _ in layers)
        mesh = block_mesh((size[0], size[1], H), (n[0], n[1], 1), layers, _grading(g, "layer_grading"))
        d = g.get("indenter_diameter")
        if d is not None:
            r = 0.5 * bounded(d, "m", "geometry.indenter_diameter", 0.0, float(min(size)))
            x = mesh.nodes
            c = np.array([size[0] / 2, size[1] / 2])
            top = np.zeros(mesh.n_nodes, bool)
            top[mesh.node_sets["top"]] = True
            ind = top & (np.hypot(x[:, 0] - c[0], x[:, 1] - c[1]) <= r * (1 + 1e-9))
            if not ind.any():
                raise ModelError("geometry.indenter_diameter", "no top node lies under the indenter")
            mesh.node_sets["indenter"] = np.flatnonzero(ind)
        return mesh, None
    from skinkit.fem.twopad import twopad_from_spec
    return twopad_from_spec(g, layers), None


#: accepted number of load steps of a programme
MAX_STEPS = 100_000
#: accepted programme durations and periods [s]
DURATION_RANGE = (0.0, 1e6)
#: accepted sinusoid frequencies [Hz]
FREQUENCY_RANGE = (1e-6, 1e4)


def _plausible(v: np.ndarray, unit: str, entry: str, extent: float) -> None:
    """A displacement no larger than the model (``extent`` [m]) or a force up to
    :data:`MAX_FORCE_N`."""
    with np.errstate(over="ignore"):  # a norm of 1e300 overflows to inf, which is refused below
        mag = float(np.linalg.norm(v))
    limit = MAX_FORCE_N if unit == "N" else extent
    if mag > limit:
        raise ModelError(entry, f"magnitude {mag:g} {unit} is outside the plausible range "
                         f"[0, {limit:g}] {unit}"
                         + ("" if unit == "N" else " (the model's largest dimension)"))


def _load(spec: Mapping[str, Any], unit: str, extent: float = math.inf) -> LoadProgramme:
    d = table(_get(spec, "load", ""), "load")
    kind = d.get("kind", "ramp")
    if kind == "ramp":
        _check_keys(d, {"kind", "value", "steps", "duration"}, "load")
        v = vector(_get(d, "value", "load"), unit, "load.value")
        _plausible(v, unit, "load.value", extent)
        n = integer(d.get("steps", 10), "load.steps", 1, MAX_STEPS)
        if "duration" in d:
            T = bounded(d["duration"], "s", "load.duration", *DURATION_RANGE)
            return LoadProgramme(np.linspace(T / n, T, n), True, lambda t: min(t / T, 1.0) * v,
                                 f"ramp to {v} over {T} s")
        return LoadProgramme(np.linspace(1 / n, 1, n), False, lambda t: t * v, f"static ramp to {v}")
    if kind == "sinusoid":
        _check_keys(d, {"kind", "peak_to_peak", "frequency", "periods", "steps_per_period",
                        "direction"}, "load")
        pp = quantity(_get(d, "peak_to_peak", "load"), unit, "load.peak_to_peak")
        _plausible(np.array([pp]), unit, "load.peak_to_peak", extent)
        f = bounded(_get(d, "frequency", "load"), "Hz", "load.frequency", *FREQUENCY_RANGE, lo_open=False)
        periods = bounded(d.get("periods", 3), "1", "load.periods", 0.0, float(MAX_STEPS))
        spp = integer(d.get("steps_per_period", 20), "load.steps_per_period", 1, MAX_STEPS)
        n = periods * spp
        if abs(n - round(n)) > 1e-9 * max(n, 1.0):
            raise ModelError("load.periods", f"periods x steps_per_period must be a whole number of "
                             f"steps, got {periods:g} x {spp} = {n:g}")
        n = int(round(n))
        if n > MAX_STEPS:
            raise ModelError("load.periods", f"periods x steps_per_period = {n} steps, over the limit of "
                             f"{MAX_STEPS}")
        raw = d.get("direction", [0.0, 0.0, -1.0])
        try:
            direc = np.asarray(raw, dtype=float)
        except (TypeError, ValueError):
            direc = np.zeros(0)
        if direc.shape != (3,) or not np.all(np.isfinite(direc)) or np.linalg.norm(direc) == 0:
            raise ModelError("load.direction", f"expected a non-zero 3-vector of numbers, got {raw!r}")
        direc = direc / np.linalg.norm(direc)
        T = periods / f
        return LoadProgramme(np.linspace(T / n, T, n), True,
                             lambda t: 0.5 * pp * (1 - math.cos(2 * math.pi * f * t)) * direc,
                             f"sinusoid {pp} peak to peak at {f} Hz, {periods} periods")
    if kind == "table":
        _check_keys(d, {"kind", "times", "values", "viscous"}, "load")
        times, vals = _get(d, "times", "load"), _get(d, "values", "load")
        for key, x in (("times", times), ("values", vals)):
            if not isinstance(x, list) or not 1 <= len(x) <= MAX_STEPS:
                raise ModelError(f"load.{key}", f"expected a list of 1 to {MAX_STEPS} entries, got {x!r}")
        t = np.array([quantity(x, "s", f"load.times[{i}]") for i, x in enumerate(times)])
        if len(vals) != t.size:
            raise ModelError("load.values",
                             f"expected one value per time: {t.size} times, {len(vals)} values")
        if np.any(np.diff(t) <= 0) or t[0] <= 0:
            raise ModelError("load.times", "times must be positive and increasing")
        V = np.array([vector(v, unit, f"load.values[{i}]") for i, v in enumerate(vals)])
        for i, v in enumerate(V):
            _plausible(v, unit, f"load.values[{i}]", extent)
        tt = np.concatenate([[0.0], t])
        VV = np.vstack([np.zeros(3), V])
        return LoadProgramme(t, flag(d.get("viscous", True), "load.viscous"),
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
    meta = table(spec.get("model", {}), "model")
    name = text(meta.get("name", "model"), "model.name")
    layers_spec = _get(spec, "layers", "")
    if not isinstance(layers_spec, list) or not layers_spec:
        raise ModelError("layers", "needs at least one [[layers]] table")
    layers, mats = [], []
    for i, L in enumerate(layers_spec):
        entry = f"layers[{i}]"
        _check_keys(L, {"name", "thickness", "elements", "law", "options", "parameters", "prestress",
                        "bounds"}, entry)
        lname = text(_get(L, "name", entry), f"{entry}.name")
        th = bounded(_get(L, "thickness", entry), "m", f"{entry}.thickness", *LENGTH_RANGE)
        layers.append((lname, th, integer(L.get("elements", 2), f"{entry}.elements", 1,
                                          MAX_ELEMENTS_PER_DIRECTION)))
        law = _law(L, entry)
        F0, pre = _prestress(L.get("prestress"), f"{entry}.prestress")
        params = table(L.get("parameters", {}), f"{entry}.parameters")
        values = _params(law, params, entry)
        mats.append(Material(lname, law, values, F0=F0, prestress=pre,
                             bounds=_fit_bounds(law, L.get("bounds"), values, f"{entry}.bounds")))
    if len({n for n, _, _ in layers}) != len(layers):
        raise ModelError("layers", "layer names must be unique")
    sol = table(spec.get("solver", {}), "solver")
    _check_keys(sol, {"linear", "rtol", "atol", "max_iter", "max_cuts", "line_search", "intorder",
                      "max_unknowns", "discretisation_tolerance", "point_tolerance"}, "solver")
    intorder = integer(sol.pop("intorder", 4), "solver.intorder", *INTORDER_RANGE)
    if "max_unknowns" in sol:
        max_unknowns(spec)  # a bad limit is refused here, with the other [solver] entries
    sol.pop("max_unknowns", None)
    disc_tol, point_tol = _discretisation_tolerances(sol)
    options = _solver_options(sol)
    if mesh is None:
        check_size(spec, layers)  # before building: a huge mesh is refused, not attempted
        mesh, _ = _mesh(spec, layers)
        check_thinness(mesh)
    elif 3 * mesh.n_nodes > max_unknowns(spec):
        raise ModelError("geometry", f"the mesh has {3 * mesh.n_nodes:,} unknowns, over the limit of "
                         f"{max_unknowns(spec):,} ([solver] max_unknowns or SKINKIT_MAX_UNKNOWNS)")
    from skinkit.fem.fields import read_fields
    fields = read_fields(spec.get("fields"), [n for n, _, _ in layers], quantity)
    problem = Problem(mesh, mats, intorder=intorder, fields=fields)
    bd = table(spec.get("boundary", {}), "boundary")
    _check_keys(bd, {"fixed", "compliance"}, "boundary")
    fixed = bd.get("fixed", ["outer", "bottom"] if "outer" in mesh.node_sets else ["bottom"])
    if isinstance(fixed, str):
        fixed = [fixed]
    if not isinstance(fixed, list) or not all(isinstance(s, str) for s in fixed):
        raise ModelError("boundary.fixed", f"expected a list of node-set names, got {fixed!r}")
    fixed = list(fixed)
    bc = BoundaryConditions(mesh.n_dof)
    fixed = _elastic_supports(bd.get("compliance"), mesh, fixed, bc)
    for s in fixed:
        if s not in mesh.node_sets:
            raise ModelError("boundary.fixed", f"no node set {s!r}; sets are {sorted(mesh.node_sets)}")
        bc.fix(mesh.node_sets[s])
    extent = float(np.ptp(mesh.nodes, axis=0).max())
    load = _indenter_and_load(spec, mesh, fixed, bc, extent, require_load)
    outp = table(spec.get("output", {}), "output")
    _check_keys(outp, {"points", "point_depth", "sensitivities"}, "output")
    points = None
    if "points" in outp:
        raw = outp["points"]
        if not isinstance(raw, list) or not raw:
            raise ModelError("output.points", "expected a list of [x, y, z] points")
        points = np.array([vector(p, "m", f"output.points[{i}]") for i, p in enumerate(raw)])
    depth = bounded(outp.get("point_depth", 0.0), "m", "output.point_depth", 0.0, extent, lo_open=False)
    return Model(name, spec, mesh, problem, bc, load, options, intorder, fixed, points, depth,
                 flag(outp.get("sensitivities", False), "output.sensitivities"), fields, disc_tol, point_tol)


def _indenter_and_load(spec: Mapping[str, Any], mesh: FEMesh, fixed: list[str],
                       bc: BoundaryConditions, extent: float, require_load: bool) -> Any:
    """The ``[indenter]`` (a rigid set of nodes driven in displacement or force, set on
    ``bc``) and the ``[load]`` programme in its unit; ``extent`` [m] bounds a displacement."""
    ind = spec.get("indenter")
    unit = "m"
    if ind is not None:
        _check_keys(ind, {"mode", "components"}, "indenter")
        mode = ind.get("mode", "displacement")
        if mode not in ("displacement", "force"):
            raise ModelError("indenter.mode", f"must be 'displacement' or 'force', got {mode!r}")
        unit = "N" if mode == "force" else "m"
        comps = ind.get("components", [0, 1, 2])
        if (not isinstance(comps, list) or not comps or len(set(map(repr, comps))) != len(comps)
                or any(isinstance(c, bool) or c not in (0, 1, 2) for c in comps)):
            raise ModelError("indenter.components", f"expected a list of distinct components from "
                             f"0, 1, 2 (x, y, z), got {comps!r}")
        if "indenter" not in mesh.node_sets:
            raise ModelError("indenter", "the geometry has no indenter region (set indenter_diameter)")
        nodes = mesh.node_sets["indenter"]
        fixed_nodes = np.concatenate([mesh.node_sets[s] for s in fixed]) if fixed else np.zeros(0, int)
        nodes = np.setdiff1d(nodes, fixed_nodes)
        load = _load(spec, unit, extent) if (require_load or "load" in spec) else _no_load()
        bc.rigid = Rigid(nodes, mode, load.value, tuple(int(c) for c in comps))
    else:
        load = _load(spec, unit, extent) if (require_load or "load" in spec) else _no_load()
    return load


#: accepted ``[solver]`` relative and absolute tolerances, Newton iterations and step cuts
RTOL_RANGE, ATOL_RANGE = (0.0, 0.1), (0.0, 1e3)
MAX_ITER_RANGE, MAX_CUTS_RANGE = (1, 1000), (0, 60)


#: accepted ``[solver] discretisation_tolerance`` (relative) and ``point_tolerance`` [m]
DISCRETISATION_TOLERANCE_RANGE, POINT_TOLERANCE_RANGE = (0.0, 0.5), (0.0, 0.01)


def _discretisation_tolerances(sol: dict[str, Any]) -> tuple[float | None, float | None]:
    """``[solver] discretisation_tolerance`` (relative, e.g. 0.05) and ``point_tolerance``
    (a length), checked and removed from ``sol``; None where absent."""
    tol = sol.pop("discretisation_tolerance", None)
    ptol = sol.pop("point_tolerance", None)
    if tol is not None:
        tol = bounded(tol, "1", "solver.discretisation_tolerance", *DISCRETISATION_TOLERANCE_RANGE)
    if ptol is not None:
        ptol = bounded(ptol, "m", "solver.point_tolerance", *POINT_TOLERANCE_RANGE)
    return tol, ptol


def _solver_options(sol: Mapping[str, Any]) -> SolverOptions:
    """``[solver]`` entries (``intorder``, ``max_unknowns`` and the discretisation tolerances
    removed), checked."""
    kw: dict[str, Any] = {}
    if "rtol" in sol:
        kw["rtol"] = bounded(sol["rtol"], "1", "solver.rtol", *RTOL_RANGE)
    if "atol" in sol:
        kw["atol"] = bounded(sol["atol"], "N", "solver.atol", *ATOL_RANGE, lo_open=False)
    if "max_iter" in sol:
        kw["max_iter"] = integer(sol["max_iter"], "solver.max_iter", *MAX_ITER_RANGE)
    if "max_cuts" in sol:
        kw["max_cuts"] = integer(sol["max_cuts"], "solver.max_cuts", *MAX_CUTS_RANGE)
    if "line_search" in sol:
        kw["line_search"] = flag(sol["line_search"], "solver.line_search")
    if "linear" in sol:
        from skinkit.fem.linsolve import resolve
        kw["linear"] = text(sol["linear"], "solver.linear")
        resolve(kw["linear"])  # an unknown or missing solver is refused before any work
    return SolverOptions(**kw)


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
    still = [s for s in fixed if s not in sets]
    held = np.zeros(mesh.n_nodes, bool)     # nodes another set keeps fixed whatever c is
    for s in still:
        if s in mesh.node_sets:
            held[mesh.node_sets[s]] = True
    areas = {s: nodal_areas(mesh, mesh.node_sets[s]) for s in sets}
    area = np.zeros(mesh.n_nodes)
    on = np.zeros(mesh.n_nodes, bool)
    for s in sets:     # a node of two sets: both springs
        nodes = mesh.node_sets[s]
        area[nodes] += areas[s][nodes]
        on[nodes] = True
    rim = np.flatnonzero(on & ~held & (area > 0))
    bc.compliance = ComplianceSupport((3 * rim[:, None] + np.arange(3)).ravel(), np.repeat(area[rim], 3), c)
    if c == 0:
        return fixed
    for s in sets:
        nodes = mesh.node_sets[s]
        bc.support(nodes, areas[s][nodes] / c)
    return still


#: nodal areas already integrated, by mesh and node set: a model is built several times per
#: prediction (and per worker), the facet basis each time took a quarter of a second
_AREAS: dict[str, np.ndarray] = {}


def nodal_areas(mesh: FEMesh, nodes: np.ndarray) -> np.ndarray:
    """``(N,)`` ∫ Nₐ dA over the boundary faces whose nodes all lie in ``nodes`` [m²]."""
    import hashlib

    key = hashlib.sha1(mesh.nodes.tobytes() + mesh.elements.tobytes()
                       + np.asarray(nodes, np.int64).tobytes()).hexdigest()
    if key not in _AREAS:
        if len(_AREAS) >= 32:
            _AREAS.pop(next(iter(_AREAS)))
        _AREAS[key] = _nodal_areas(mesh, nodes)
    return _AREAS[key].copy()


def _nodal_areas(mesh: FEMesh, nodes: np.ndarray) -> np.ndarray:
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
    layers = _get(spec, "layers", "")
    if not isinstance(layers, list) or not layers:
        raise ModelError("layers", "needs at least one [[layers]] table")
    for i, L in enumerate(layers):
        entry = f"layers[{i}]"
        L = table(L, entry)
        out.append((str(_get(L, "name", entry)),
                    bounded(_get(L, "thickness", entry), "m", f"{entry}.thickness", *LENGTH_RANGE),
                    integer(L.get("elements", 2), f"{entry}.elements", 1, MAX_ELEMENTS_PER_DIRECTION)))
    return out


def build_mesh(spec: Mapping[str, Any]) -> FEMesh:
    """The mesh of a model description (before any surface fitting)."""
    return _mesh(spec, layer_table(spec))[0]
