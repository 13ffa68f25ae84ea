"""The finite-element forward model: a model file driven by a session, predicting what it measured.

For each protocol of the session the recorded tip force (``[indenter] mode = "force"``, the
thesis's choice) or tip position (``"displacement"``) drives the rigid indenter; the top of
the mesh is fitted to the session's profile (``[surface] fit``); the tracked points are put on
the fitted surface and embedded ``[output] point_depth`` below it along the true normal; the
model is solved at steps no longer than ``[drive] max_step`` (and at every camera frame) and
its tip motion or force and the points' positions are interpolated onto exactly the observed
times (cubic in time between solved steps; frames are solved steps).

Sensitivities: law, pre-stretch, field and drive parameters by direct differentiation
(``skinkit.fem.sensitivity``), through viscous histories; instrument parameters analytically
(``skinkit.forward.instrument``); effect parameters bound to any of these under the
effect's name; effect parameters declared as geometry (a layer's thickness) by the shape
derivative through the same pass (``skinkit.forward.fe_geometry``); anything else by central
differences of whole solves.

Protocols are independent solves: they run in worker processes (``workers``, default one
per core) or on a Dask cluster (``scheduler``); every solve uses one thread, so the numbers
do not depend on where or how many solves run at once — but with fewer protocols than workers
the idle cores go to each one's sparse solver (the same numbers to rounding, not bit for bit).

Progress: a prediction reports the fraction of its solver steps done
(:func:`skinkit.forward.stages.report`), step by step from the worker processes too, so a caller
showing progress sees a long solve advance.
"""

from __future__ import annotations

import copy
import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from skinkit.errors import ForwardError, SchemaError
from skinkit.forward import drive as drive_mod
from skinkit.forward import solve_cache, stages
from skinkit.forward.effects import AppliedEffect, apply_all
from skinkit.forward.fe_differences import central_differences
from skinkit.forward.solve_progress import SolveProgress, gather, init_worker, step_reporter
from skinkit.interfaces import ForwardModel
from skinkit.schemas import ChannelPrediction, Observations, Parameter, ParameterSet, Prediction

#: default largest solver step [s]: 20 steps per period of the thesis's 0.1 Hz protocols
DEFAULT_MAX_STEP = 0.5


@dataclass
class ProtocolJob:
    """Everything one worker needs to solve one protocol (picklable)."""

    name: str
    spec: dict[str, Any]
    nodes: np.ndarray | None              # fitted mesh node positions, or None (the geometry's)
    mode: str                             # "force" | "displacement"
    times: np.ndarray                     # (n,) solver output times [s]
    drive: np.ndarray                     # (n, 3) drive at those times [N or m], skin frame
    drive_d: dict[str, np.ndarray]        # drive parameter -> (n, 3) derivative
    level: np.ndarray | None              # (n,) softening level, or None
    embed: tuple[np.ndarray, np.ndarray] | None   # (element (P,), local (P, 3)) of tracked points
    sens: list[str]                       # FE parameter names to differentiate
    options: dict[str, Any] = field(default_factory=dict)
    strokes: np.ndarray | None = None     # (n,) loading strokes so far [1], or None
    # geometry parameter -> design velocity of the nodes (N, 3) and their depths (N,) [m per unit]
    shapes: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    shape_points: dict[str, np.ndarray] = field(default_factory=dict)   # -> (P, 3) points' dX/dp
    threads: int = 1    # the sparse solver's: more where workers outnumber protocols (set after caching)


def _interp_table(times: np.ndarray, values: np.ndarray) -> Callable[[float], np.ndarray]:
    tt = np.concatenate([[0.0], times])
    vv = np.vstack([np.zeros((1, values.shape[1])), values]) if values.ndim == 2 else \
        np.concatenate([[values[0] * 0], values])

    def f(t: float) -> np.ndarray:
        if values.ndim == 1:
            return float(np.interp(t, tt, vv))
        return np.array([np.interp(t, tt, vv[:, c]) for c in range(vv.shape[1])])
    return f


def solve_protocol(job: ProtocolJob, on_fraction: Callable[[float], None] | None = None) -> dict[str, Any]:
    """Solve one protocol; the outputs at ``[0, *job.times]`` (the first row is the unloaded
    state) with their derivatives. One thread, its sparse solver ``job.threads`` (module docstring).
    ``on_fraction(f)``: told the fraction of the output steps solved after each one."""
    from threadpoolctl import threadpool_limits

    from skinkit.fem import linsolve
    from skinkit.fem.model import build_model
    from skinkit.fem.solver import NewtonSolver
    from skinkit.forward.allocator import keep_large_blocks

    keep_large_blocks()     # a Dask worker's environment maps every large array afresh
    # load the sparse solver's libraries (MKL) first: a thread limit set before a library is
    # loaded does not reach it, and a solve with two threads differs in the last bits
    linsolve.make(str(dict(job.spec.get("solver", {}) or {}).get("linear", "auto")))
    with threadpool_limits(limits=1):
        t0 = time.perf_counter()
        spec = copy.deepcopy(job.spec)
        spec.setdefault("indenter", {})["mode"] = job.mode
        from skinkit.fem.model import build_mesh
        mesh = build_mesh(spec)
        if job.nodes is not None:
            mesh = mesh.with_nodes(job.nodes)
        model = build_model(spec, require_load=False, mesh=mesh)
        rigid = model.bc.rigid
        if rigid is None:
            raise ForwardError("indenter", "the model has no indenter (rigid region) for the drive")
        rigid.programme = _interp_table(job.times, job.drive)
        rigid.derivatives = {n: _interp_table(job.times, d) for n, d in job.drive_d.items()}
        for f in model.problem.fields:
            if f.kind == "softening":
                none = 0 * job.times
                f.level = _interp_table(job.times, job.level if job.level is not None else none)
                f.strokes = _interp_table(job.times, job.strokes if job.strokes is not None else none)
        solver = NewtonSolver(model.problem, model.bc, model.options)
        if job.threads > 1:
            solver.linear.use_threads(job.threads)
        series = _field_series(job, model)
        from skinkit.forward import fe_geometry
        shapes = fe_geometry.velocities(spec, mesh, job.shapes, model) if job.shapes else None
        sol = solver.run(job.times, viscous_time=model.problem.viscous, sensitivities=job.sens or False,
                         extrapolate=job.options.get("extrapolate", True),
                         on_step=None if series is None else series[1],
                         progress=step_reporter(job.name, job.times, on_fraction), shapes=shapes)
        n = len(job.times) + 1
        P = 0 if job.embed is None else len(job.embed[0])
        npar = len(job.sens)
        tip_u = np.zeros((n, 3))
        tip_f = np.zeros((n, 3))
        pts = np.zeros((n, P, 3))
        d_tip_u = np.zeros((n, 3, npar))
        d_tip_f = np.zeros((n, 3, npar))
        d_pts = np.zeros((n, P, 3, npar))
        emb = None
        if job.embed is not None:
            from skinkit.fem.embed import Embedding, _shape
            el, loc = job.embed
            Nv, _ = _shape(loc.T)
            emb = Embedding(el, loc, mesh.elements[el], Nv.T.copy())
            pts[0] = emb.positions(mesh.nodes)
            J = emb.position_jacobian(mesh.n_dof)
        for i, st in enumerate(sol.steps):
            tip_u[i + 1] = np.nan_to_num(st.tip_displacement)
            tip_f[i + 1] = st.tip_force
            if emb is not None:
                pts[i + 1] = emb.positions(mesh.nodes, sol.u[i])
        if npar:
            for i, sv in enumerate(sol.extra["sensitivities"]):
                col = [sv.names.index(nm) for nm in job.sens]
                d_tip_u[i + 1] = np.nan_to_num(sv.tip_displacement[:, col])
                d_tip_f[i + 1] = sv.tip_force[:, col]
                if emb is not None:
                    d_pts[i + 1] = (J @ sv.du[:, col]).reshape(P, 3, npar)
            if emb is not None and shapes:
                fe_geometry.add_point_terms(d_pts, job.sens, job.shape_points, shapes, emb, mesh.nodes, sol.u)
        untied = [c for c in range(3) if c not in rigid.components]
        tm = solver.timings
        info = {"wall_s": time.perf_counter() - t0, "steps": len(job.times),
                "increments": solver.steps_taken, "newton_iterations": tm.iterations,
                "newton_per_step": tm.iterations / max(solver.steps_taken, 1),
                "factorisations": tm.factorisations, "back_substitutions": tm.back_substitutions,
                "assembly_s": tm.assembly, "linear_solve_s": tm.solve, "n_dof": mesh.n_dof,
                "linear_solver": solver.linear.name, "threads": job.threads, "process": os.getpid()}
        if series is not None:
            info["vtu"] = str(series[0].close())
        return {"name": job.name, "times": np.concatenate([[0.0], job.times]), "tip_u": tip_u,
                "tip_f": tip_f, "points": pts, "d_tip_u": d_tip_u, "d_tip_f": d_tip_f, "d_points": d_pts,
                "untied": untied, "col_names": list(job.sens), "info": info}


def _field_series(job: ProtocolJob, model: Any) -> tuple[Any, Callable[[float, np.ndarray], None]] | None:
    """With ``job.options["vtu"]`` (a folder): the protocol's PVD series
    (:class:`skinkit.fem.vtu.Series`, its unloaded state written) and the solver's ``on_step``
    that writes each solved step into it; else None."""
    if not job.options.get("vtu"):
        return None
    from skinkit.fem import vtu

    series = vtu.Series(job.options["vtu"], job.name, model.mesh)
    viscous = model.problem.viscous
    series.write(0.0, vtu.point_data(model.problem, np.zeros(model.mesh.n_dof)))

    def on_step(t: float, u: np.ndarray) -> None:
        series.write(t, vtu.point_data(model.problem, u, viscous))
    return series, on_step


def _instrument() -> Any:
    """The instrument transforms (``skinkit.forward.instrument``)."""
    from skinkit.forward import instrument

    return instrument


#: 3-point Gauss rule on [-1, 1]: abscissae and weights
_GAUSS3 = (np.array([0.0, -math.sqrt(0.6), math.sqrt(0.6)]), np.array([8.0, 5.0, 5.0]) / 9.0)


#: step [SI: 1 for a scale, rad for a rotation] of the central differences of a tracked point's
#: embedding in a similarity parameter (1e-4: 0.8 µm at 8 mm from the origin, far inside an
#: element, where the interpolated field is smooth; truncation O(h²) ≈ 1e-8 relative)
SIMILARITY_STEP = 1e-4


def window_offsets(window_m: float) -> np.ndarray:
    """``(9, 3)`` [m] in-plane offsets of the 3 x 3 Gauss points of a square window of side
    ``window_m`` [m] (the centre first): a subset tracker's value is its subset's mean motion,
    which this rule integrates exactly for fields up to fifth order in each direction."""
    a = _GAUSS3[0] * window_m / 2
    X, Y = np.meshgrid(a, a, indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel(), np.zeros(9)])


def window_weights() -> np.ndarray:
    """``(9,)`` weights of the points of :func:`window_offsets` (summing to 1): the window's mean."""
    return np.outer(_GAUSS3[1], _GAUSS3[1]).ravel() / 4.0


def window_mean(points: np.ndarray, d_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions ``(n, P, 3)`` of windowed points from their Gauss points' ``(n, 9 P, 3)``: the
    centre's rest position plus the window's mean displacement; derivatives ``(n, 9 P, 3, p)``
    likewise (rest positions do not depend on the parameters)."""
    n = points.shape[0]
    w = window_weights()
    q = points.reshape(n, -1, 9, 3)
    mean_u = np.einsum("q,npqc->npc", w, q - q[:1])
    dq = d_points.reshape(n, q.shape[1], 9, 3, d_points.shape[-1])
    return q[:1, :, 0] + mean_u, np.einsum("q,npqcj->npcj", w, dq)


def _cubic(t_knots: np.ndarray, y: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Cubic-spline interpolation along axis 0 (not-a-knot; linear with < 4 knots)."""
    from scipy.interpolate import CubicSpline

    t = np.clip(t, t_knots[0], t_knots[-1])
    if len(t_knots) < 4:
        flat = y.reshape(len(t_knots), -1)
        out = np.stack([np.interp(t, t_knots, flat[:, j]) for j in range(flat.shape[1])], axis=1)
        return out.reshape((len(t),) + y.shape[1:])
    return CubicSpline(t_knots, y, axis=0)(t)


#: tracked points located in a mesh, by the mesh's nodes and elements, the points and their depth
_EMBED_CACHE: dict[str, tuple[np.ndarray, np.ndarray]] = {}


class FEForwardModel(ForwardModel):
    """A finite-element model file as a :class:`skinkit.interfaces.ForwardModel` (module docstring).

    With several workers it keeps a process pool between predictions; ``close()`` (or leaving
    a ``with`` block) shuts it down, and a later prediction starts a new one."""

    kind = "fe"

    def __init__(self, spec: Mapping[str, Any], effects: list[AppliedEffect], *,
                 workers: int | None = None, scheduler: str | Any | None = None) -> None:
        self.base = copy.deepcopy(dict(spec))
        self.base.pop("effects", None)
        # the session drives the model: a [load] table is only for `skinkit solve` alone
        self.base.pop("load", None)
        self.effects = effects
        self.name = str(self.base.get("model", {}).get("name", "model"))
        self.workers = workers
        self.scheduler = scheduler
        self._pool = None
        self._steps: Any = None    # the workers' step reports (a queue), made with the pool
        self.last_info: dict[str, Any] = {}
        eff = apply_all(self.base, effects)
        from skinkit.fem.model import build_model
        self._check = build_model(eff, require_load=False)   # validates the description now
        from skinkit.forward import instrument as inst_mod
        inst_mod.check_drive(inst_mod.parse(eff.get("instrument")), self._drive_channel(eff)[1])
        self._pset = self._parameters(eff)

    # -- parameters ------------------------------------------------------------------------
    def _parameters(self, eff: Mapping[str, Any]) -> ParameterSet:
        from skinkit.fem.sensitivity import PRESTRESS_NAMES
        out: list[Parameter] = []
        bound = dict(eff.get("bindings", {}))
        hidden = set(bound.values())
        effect_names = {f"{e.name}.{k}" for e in self.effects for k in e.declared}
        for m in self._check.problem.materials:
            for q in m.law.parameters():
                nm = f"{m.region}.{q.name}"
                if nm not in hidden:
                    lo, hi = m.bounds.get(q.name, (q.lower, q.upper))
                    out.append(Parameter(nm, float(m.params[q.name]), q.unit, lo, hi))
            if m.prestress is not None:
                for i, (pn, unit, lo, hi) in enumerate(zip(PRESTRESS_NAMES, ("1", "1", "rad"),
                                                           (0.5, 0.5, -math.pi / 2), (2.0, 2.0, math.pi / 2),
                                                           strict=True)):
                    nm = f"{m.region}.{pn}"
                    if nm not in hidden:
                        out.append(Parameter(nm, m.prestress[i], unit, lo, hi))
        from skinkit.fem.fields import UNITS
        effect_fields = {e.name for e in self.effects}
        for f in self._check.problem.fields:
            if f.name in effect_fields:   # an effect's field: its declared parameters stand for it
                continue
            for key, v in f.params.items():
                nm = f"{f.name}.{key}"
                if nm not in effect_names:
                    out.append(Parameter(nm, v, UNITS[key], -math.inf, math.inf))
        from skinkit.forward import instrument as inst_mod
        out += inst_mod.parameters(inst_mod.parse(eff.get("instrument")),
                                   {p.name for p in out} | set(effect_names))
        for e in self.effects:
            out.extend(e.parameter_set())
        return ParameterSet(out)

    def parameters(self) -> ParameterSet:
        """Every parameter of the model, values from the model file (effects at their values)."""
        return self._pset

    # -- descriptions at given parameter values -------------------------------------------------
    def description(self, params: ParameterSet | Mapping[str, float]) -> dict[str, Any]:
        """The model description with ``params`` (name -> SI value) written in (effects applied)."""
        values = params.values() if isinstance(params, ParameterSet) else dict(params)
        unknown = sorted(set(values) - set(self._pset.names))
        if unknown:
            raise SchemaError("parameters", f"unknown parameter(s) {unknown} for model {self.name!r}")
        spec = apply_all(self.base, self.effects, values)
        layers = {str(L["name"]): L for L in spec["layers"]}
        for nm, v in values.items():
            region, _, local = nm.partition(".")
            if region in layers and local.startswith("prestretch."):
                pre = layers[region].setdefault("prestress", {})
                st = list(pre.get("stretch", [1.0, 1.0]))
                if local == "prestretch.angle":
                    pre["angle"] = float(v)
                else:
                    st[int(local[-1]) - 1] = float(v)
                    pre["stretch"] = [float(x) for x in st]
            elif region in layers:
                layers[region].setdefault("parameters", {})[local] = float(v)
        for f in spec.get("fields", []) or []:
            if f.get("name") in {e.name for e in self.effects}:
                continue
            for key in list(f):
                nm = f"{f['name']}.{key}"
                if nm in values and nm not in {f"{e.name}.{k}" for e in self.effects for k in e.declared}:
                    f[key] = float(values[nm])
        for ent in spec.get("instrument", []) or []:
            nm = str(ent.get("parameter", ""))
            if nm in values and nm not in {f"{e.name}.{k}" for e in self.effects for k in e.declared}:
                ent["value"] = float(values[nm])
        return spec

    def _classify(self, spec: Mapping[str, Any], names: Sequence[str]) -> dict[str, tuple[str, str]]:
        """parameter -> (method, internal name): "fe" (engine), "instrument", "shape" (an
        effect's geometry parameter), "fd"."""
        from skinkit.fem.model import build_model
        probe = build_model(spec, require_load=False)
        from skinkit.fem.sensitivity import parameter_names as fe_names
        fe = set(fe_names(probe.problem, compliance=probe.bc.compliance))
        inst = {str(e.get(k)) for e in spec.get("instrument", []) or []
                for k in ("parameter", "azimuth_parameter", "tau_parameter") if e.get(k)}
        bind = dict(spec.get("bindings", {}))
        from skinkit.forward.fe_geometry import geometry_parameters
        geo = geometry_parameters(self.effects)
        out = {}
        for nm in names:
            target = bind.get(nm, nm)
            if target in fe:
                out[nm] = ("fe", target)
            elif target in inst:
                out[nm] = ("instrument", target)
            elif nm in geo:
                out[nm] = ("shape", nm)
            else:
                out[nm] = ("fd", nm)
        return out

    # -- prediction --------------------------------------------------------------------------
    def predict(self, params: ParameterSet, observations: Observations,
                sensitivities: bool | Sequence[str] = False,
                progress: Callable[[str, float], None] | None = None, *,
                fields_dir: str | os.PathLike[str] | None = None) -> Prediction:
        """Predictions of every observed channel but the drive (see the module docstring).

        ``fields_dir``: also write each protocol's fields there as a PVD series
        (``<protocol>.pvd``, ``<protocol>_NNNN.vtu``: :mod:`skinkit.fem.vtu`), by the process
        that solves it; ``pred.info["protocols"][name]["vtu"]`` is its path."""
        return self.predict_many([(params, observations, sensitivities)], fields_dir=fields_dir)[0]

    def predict_many(self, calls: Sequence[tuple[ParameterSet, Observations, bool | Sequence[str]]], *,
                     fields_dir: str | os.PathLike[str] | None = None) -> list[Prediction]:
        """:meth:`predict` for each ``(params, observations, sensitivities)`` of ``calls``, their
        protocol solves handed to the workers as one batch: three protocols on two workers take
        two rounds alone, six take three together."""
        preps = [self._prepare(*c) for c in calls]
        fd = max((len(p["fd"]) for p in preps), default=0)
        share = 1.0 / (1 + 2 * fd)   # of the whole solves reported as progress
        t0 = time.perf_counter()
        with stages.portion(0.0, share):
            built = [self._solve_all(p["spec"], p["observations"], p["fe_names"], p["inst_names"], fields_dir,
                                     p["shapes"], solve=False) for p in preps]
            tag = (lambda k, name: name) if len(preps) == 1 else (lambda k, name: f"{k}:{name}")
            jobs = [replace(j, name=tag(k, j.name)) for k, (js, _) in enumerate(built) for j in js]
            solved = solve_cache.solve_jobs(jobs, self._run)
        out = []
        for k, (p, (js, meta)) in enumerate(zip(preps, built, strict=True)):
            results = {j.name: solved[tag(k, j.name)] for j in js}
            pred = self._assemble(p["spec"], p["observations"], results, meta, p["cls"], p["inst_names"])
            if p["fd"]:
                with stages.portion(share, 1.0):
                    central_differences(self, p["params"], p["observations"], pred, p["fd"])
            out.append(self._finish(pred, p["cls"], results, t0))
        return out

    def _prepare(self, params: ParameterSet, observations: Observations,
                 sensitivities: bool | Sequence[str]) -> dict[str, Any]:
        """One prediction's description, parameter routes and geometry designs (no solve)."""
        if not isinstance(observations, Observations):
            raise SchemaError("observations", f"expected Observations, got {type(observations).__name__}")
        names = self._pset.names if sensitivities is True else \
            ([] if not sensitivities else list(sensitivities))
        unknown = sorted(set(names) - set(self._pset.names))
        if unknown:
            raise SchemaError("sensitivities", f"unknown parameter(s) {unknown} for model {self.name!r}")
        spec = self.description(params)
        cls = self._classify(spec, names)
        inst_names = sorted({v[1] for v in cls.values() if v[0] == "instrument"})
        shapes = self._designs(params, observations, [nm for nm, (m, _) in cls.items() if m == "shape"],
                               inst_names)
        return {"params": params, "observations": observations, "spec": spec, "cls": cls,
                "fe_names": sorted({v[1] for v in cls.values() if v[0] == "fe"}), "inst_names": inst_names,
                "shapes": shapes, "fd": [nm for nm, (m, _) in cls.items() if m == "fd"]}

    def _finish(self, pred: Prediction, cls: Mapping[str, tuple[str, str]], results: Mapping[str, Any],
                t0: float) -> Prediction:
        """``pred`` with its derivatives' methods, the solve's counts and its ``info``."""
        for nm, (m, _) in cls.items():
            pred.methods[nm] = {"fe": "analytic", "instrument": "analytic", "shape": "analytic (shape)",
                                "fd": "central-difference"}[m]
        stages.count(len(results), len(cls), pred.methods)
        infos = [r["info"] for r in results.values()]
        steps = sum(i["increments"] for i in infos)
        pred.info = {"wall_s": time.perf_counter() - t0,
                     "protocols": {k: r["info"] for k, r in results.items()},
                     "newton_per_step": sum(i["newton_iterations"] for i in infos) / max(steps, 1),
                     "n_dof": infos[0]["n_dof"] if infos else 0}
        self.last_info = pred.info
        return pred

    def _designs(self, params: ParameterSet, observations: Observations, names: list[str],
                 inst_names: list[str]) -> dict[str, Any]:
        """Geometry parameter -> its :class:`skinkit.forward.fe_geometry.GeometryDesign` (no solve)."""
        if not names:
            return {}
        from skinkit.forward import fe_geometry as geo

        def build(p: ParameterSet):
            return geo.layout(self, p, observations, inst_names)
        base = build(params)[0]
        return {nm: geo.design(build, nm, params, base) for nm in names}

    def _surface(self, spec: Mapping[str, Any], observations: Observations):
        """The mesh (fitted to the session's profile when asked) and the point embedding per channel."""
        from skinkit.fem.embed import fit_surface
        from skinkit.fem.errors import ModelError
        from skinkit.fem.model import build_mesh, layer_table, quantity
        surf = dict(spec.get("surface", {}) or {})
        unknown = sorted(set(surf) - {"fit", "outside"})
        if unknown:
            raise ForwardError("surface", f"unknown key(s) {unknown}; allowed are ['fit', 'outside']")
        fit = surf.get("fit", "auto")
        if fit not in (True, False, "auto"):
            raise ForwardError("surface.fit", f"must be true, false or \"auto\", got {fit!r}")
        outside = surf.get("outside", "error")
        if outside not in ("error", "nearest"):
            raise ForwardError("surface.outside", f"must be \"error\" or \"nearest\", got {outside!r}")
        mesh = build_mesh(spec)
        nodes = None
        if fit is True and observations.profile is None:
            raise ForwardError("surface.fit", f"the session {observations.source!r} has no profile to fit")
        if fit and observations.profile is not None:
            prof = observations.profile.points
            top = mesh.nodes[mesh.node_sets["top"]]
            from scipy.spatial import Delaunay
            hull = Delaunay(prof[:, :2])
            keep = np.zeros(mesh.n_nodes, bool)
            for s in ("outer", "indenter", "pad_fixed"):
                if s in mesh.node_sets:
                    keep[mesh.node_sets[s]] = True
            outside_pts = (hull.find_simplex(top[:, :2]) < 0) & ~keep[mesh.node_sets["top"]]
            if outside_pts.any() and outside == "error":
                xy = top[outside_pts, :2]
                raise ForwardError("surface", f"the session's profile does not cover the mesh: "
                                   f"{int(outside_pts.sum())} of {len(top)} top nodes lie outside it "
                                   f"(e.g. at {np.round(xy[0] * 1e3, 2).tolist()} mm); profile spans "
                                   f"x {prof[:, 0].min() * 1e3:.1f}..{prof[:, 0].max() * 1e3:.1f} mm, "
                                   f"y {prof[:, 1].min() * 1e3:.1f}..{prof[:, 1].max() * 1e3:.1f} mm; set "
                                   "[surface] outside = \"nearest\" to extrapolate, or fit = false")
            skin = layer_table(spec)[0][1]
            try:
                mesh = fit_surface(mesh, prof, skin, keep=("outer", "indenter", "pad_fixed")).mesh
            except ModelError as exc:
                raise ForwardError("surface", str(exc)) from None
            nodes = mesh.nodes
        depth = quantity(dict(spec.get("output", {}) or {}).get("point_depth", 0.0), "m",
                         "output.point_depth")
        return mesh, nodes, depth

    def _embed(self, mesh, ch, depth: float, where: str, ref: np.ndarray | None = None):
        from skinkit.fem.embed import embed_points, surface_points
        from skinkit.fem.errors import ModelError
        ref = np.asarray(ch.reference if ref is None else ref, dtype=float)
        if ref.shape[1] == 2:
            ref = np.column_stack([ref, np.zeros(len(ref))])
        if ch.window_m is not None:   # each point: its subset's 3 x 3 Gauss points, centre first
            ref = (ref[:, None, :] + window_offsets(ch.window_m)[None]).reshape(-1, 3)
        # protocols of a session share their points, a fit asks again and again, and a diagnosis
        # builds model after model on the same mesh: locate once per process
        import hashlib
        key = hashlib.sha1(mesh.nodes.tobytes() + mesh.elements.tobytes() + ref.tobytes()
                           + np.float64(depth).tobytes()).hexdigest()
        cache = _EMBED_CACHE
        if key in cache:
            return cache[key]
        try:
            on, _ = surface_points(mesh, ref, depth)
            emb = embed_points(mesh, on)
        except ModelError as exc:
            raise ForwardError(where, f"tracked point outside the model: {exc}") from None
        if len(cache) > 64:
            cache.clear()
        element, local = np.array(emb.element), np.array(emb.local)
        element.setflags(write=False)   # shared by every model of the process
        local.setflags(write=False)
        cache[key] = (element, local)
        return cache[key]

    def _embed_channel(self, mesh, ch, depth: float, where: str, entries, inst_names: Sequence[str]):
        """A points channel's embedding, and its sets (None: one set at the reference). A
        measured reference under ``similarity`` entries is distorted as every frame is: the
        points are embedded where the undistorted reference puts them, and for each similarity
        parameter asked for, at ±:data:`SIMILARITY_STEP` of it too (the embedding's share of the
        derivative, by central differences of the interpolated field: no extra solve)."""
        inst_mod = _instrument()
        sims = inst_mod.similarity_parameters(entries, ch.name)
        if not sims or ch.reference_frame is None:
            return self._embed(mesh, ch, depth, where), None
        ref = np.asarray(ch.reference, dtype=float)
        diff = [p for p in sims if p in inst_names]
        refs = [inst_mod.unrecord_points(entries, ch.name, ref)]
        for p in diff:
            refs += [inst_mod.unrecord_points(entries, ch.name, ref, {p: sgn * SIMILARITY_STEP})
                     for sgn in (1, -1)]
        parts = [self._embed(mesh, ch, depth, where, r) for r in refs]
        emb = (np.concatenate([e[0] for e in parts]), np.concatenate([e[1] for e in parts]))
        return emb, {"n": len(parts), "diff": diff, "refs": refs}

    def _drive_channel(self, spec: Mapping[str, Any]) -> tuple[str, str]:
        mode = str(dict(spec.get("indenter", {}) or {}).get("mode", "force"))
        if mode not in ("force", "displacement"):
            raise ForwardError("indenter.mode", f"must be 'force' or 'displacement', got {mode!r}")
        return mode, ("tip_force" if mode == "force" else "tip_position")

    def _solve_all(self, spec, observations: Observations, fe_names: list[str], inst_names: list[str],
                   fields_dir: str | os.PathLike[str] | None = None, shapes: Mapping[str, Any] | None = None,
                   solve: bool = True):
        """``(results, meta)``: each protocol solved (``solve=False``: its job, unsolved)."""
        from skinkit.fem.model import quantity
        inst_mod = _instrument()
        mode, drive_name = self._drive_channel(spec)
        dr = dict(spec.get("drive", {}) or {})
        unknown = sorted(set(dr) - {"max_step"})
        if unknown:
            raise ForwardError("drive", f"unknown key(s) {unknown}; allowed are ['max_step']")
        max_step = quantity(dr.get("max_step", DEFAULT_MAX_STEP), "s", "drive.max_step")
        if not max_step > 0:
            raise ForwardError("drive.max_step", f"must be positive, got {max_step}")
        mesh, nodes, depth = self._surface(spec, observations)
        entries = inst_mod.parse(spec.get("instrument"))
        jobs, meta = [], {}
        drives = {}
        for po in observations:
            if drive_name not in po.channels:
                raise ForwardError(f"session protocol {po.name!r}",
                                   f"has no {drive_name!r} channel to drive the model "
                                   f"([indenter] mode = {mode!r}); it has {sorted(po.channels)}")
            ch = po.channels[drive_name]
            frames = [c.time_s for c in po.channels.values() if c.is_points]
            times = drive_mod.step_times(float(ch.time_s[-1]), max_step,
                                         np.concatenate(frames) if frames else None)
            rec = drive_mod.fill_invalid(ch.values, ch.valid)
            true, dtrue = inst_mod.drive(entries, drive_name, ch.time_s, rec, inst_names)
            window = float(np.median(np.diff(times))) if len(times) > 1 else float(times[0])
            dsteps = drive_mod.smooth_at(ch.time_s, true, times, window)
            dd = {n: drive_mod.smooth_at(ch.time_s, d, times, window) for n, d in dtrue.items()}
            drives[po.name] = (times, dsteps, dd)
            embeds, sets = {}, {}
            for c in po.channels.values():
                if c.is_points:
                    embeds[c.name], sets[c.name] = self._embed_channel(
                        mesh, c, depth, f"session protocol {po.name!r}.{c.name}", entries, inst_names)
            meta[po.name] = {"drive": drive_name, "embeds": embeds, "sets": sets}
        # softening level and loading strokes over the session, protocols in order
        ref = max((float(np.linalg.norm(d[1], axis=1).max()) for d in drives.values()), default=0.0)
        running, done = 0.0, 0.0
        for po in observations:
            times, dsteps, dd = drives[po.name]
            level = drive_mod.running_level(dsteps, running, ref)
            strokes = drive_mod.running_strokes(dsteps, done, ref)
            running = max(running, float(np.linalg.norm(dsteps, axis=1).max()))
            done = float(strokes[-1])
            emb = None
            embeds = meta[po.name]["embeds"]
            if embeds:
                els = np.concatenate([e[0] for e in embeds.values()])
                locs = np.concatenate([e[1] for e in embeds.values()])
                emb = (els, locs)
            geo = dict(shapes or {})
            jobs.append(ProtocolJob(po.name, spec, nodes, mode, times, dsteps, dd, level, emb,
                                    list(fe_names) + list(geo) + list(dd), strokes=strokes,
                                    options={"vtu": str(fields_dir)} if fields_dir is not None else {},
                                    shapes={n: (g.nodes, g.depth) for n, g in geo.items()},
                                    shape_points={n: g.points[po.name] for n, g in geo.items()}))
        if not solve:
            return jobs, meta
        return solve_cache.solve_jobs(jobs, self._run), meta

    def _run(self, jobs: list[ProtocolJob]) -> dict[str, dict[str, Any]]:
        if self.scheduler is not None:
            return self._run_dask(jobs)
        wanted = max(1, self.workers if self.workers is not None else (os.cpu_count() or 1))
        workers = max(1, min(wanted, len(jobs)))     # no job at all: nothing to start
        if jobs and wanted >= 2 * len(jobs):    # a one-protocol record: idle cores to its solver
            jobs = [replace(j, threads=wanted // len(jobs)) for j in jobs]
        tracker = SolveProgress(jobs)
        if workers == 1:
            return {j.name: solve_protocol(j, lambda f, n=j.name: tracker(n, f)) for j in jobs}
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor
        if self._pool is None or self._pool_size != workers:
            self.close()
            ctx = multiprocessing.get_context("spawn")
            self._steps = ctx.SimpleQueue()
            self._pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                                             initializer=init_worker, initargs=(self._steps,))
            self._pool_size = workers
        futures = [self._pool.submit(solve_protocol, j) for j in jobs]
        try:
            return gather(futures, self._steps, tracker)
        except Exception:
            for f in futures:   # a failed solve: the others of this prediction are not wanted
                f.cancel()
            raise
        except BaseException:
            # Ctrl-C: end the running solves now rather than wait for them, leaving nothing behind
            self.close(now=True)
            raise

    def _run_dask(self, jobs: list[ProtocolJob]) -> dict[str, dict[str, Any]]:
        try:
            from dask.distributed import Client
        except ImportError:
            raise ForwardError("--scheduler",
                               "needs dask.distributed (pip install 'skinkit[cluster]')") from None
        sched = self.scheduler
        address = sched if isinstance(sched, str) else getattr(sched, "scheduler_address", sched)
        try:
            client = Client(address, timeout="10s", set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise ForwardError("--scheduler",
                               f"cannot reach the Dask scheduler at {address!r}: {exc}") from None
        try:
            futures = client.map(solve_protocol, jobs, pure=False)
            return {r["name"]: r for r in client.gather(futures)}
        finally:
            client.close()

    def refined(self, factor: int) -> FEForwardModel:
        """The same model on a mesh with every element count multiplied by ``factor`` (same
        effects, workers and scheduler): the discretisation check's model
        (:mod:`skinkit.inverse.discretisation`)."""
        from skinkit.fem.discretisation import refined_spec
        return FEForwardModel(refined_spec(self.base, factor), self.effects, workers=self.workers,
                              scheduler=self.scheduler)

    def close(self, now: bool = False) -> None:
        """Shut the worker processes down (they are kept between predictions otherwise);
        idempotent. ``now``: end running solves too (after an interrupt) instead of waiting."""
        if self._pool is not None:
            if now:
                for proc in list((getattr(self._pool, "_processes", None) or {}).values()):
                    proc.terminate()
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if getattr(self, "_steps", None) is not None:
            self._steps.close()
            self._steps = None

    def __del__(self) -> None:  # pragma: no cover - interpreter shutdown order varies
        try:
            self.close()
        except Exception:
            pass

    @staticmethod
    def _points(r, po, meta, tk, col_names) -> dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]:
        """Each points channel of protocol ``po``: positions ``(P, T, k)`` at the record's frames
        and their derivatives (the embedding's own, by differences, for similarity parameters).

        With a measured reference (``reference_frame``) a track knows positions only relative to
        that frame: the prediction is the (undistorted) reference plus the model's displacement
        since that frame, so the reference frame is predicted exactly as recorded in every
        component. Without it the embedded point's own position would stand in for the reference,
        dropping the reference's noise normal to the surface (the points are embedded on it), and
        the residuals' frame-to-frame correlation would no longer be the one :meth:`Channel.whiten`
        removes (χ²/N of the points 0.97 on sessions whose model is exact)."""
        true = {}
        start = 0
        for cname, (el, _) in meta["embeds"].items():
            P = len(el)
            ch = po.channels[cname]
            sets = meta.get("sets", {}).get(cname) or {"n": 1, "diff": []}
            Ps = P // sets["n"]
            k = ch.values.shape[2]
            f0 = ch.reference_frame
            refs = sets.get("refs") or ([ch.reference] if f0 is not None else None)
            pts_sets = []
            for i in range(sets["n"]):
                raw = r["points"][:, start + i * Ps:start + (i + 1) * Ps]
                dp = r["d_points"][:, start + i * Ps:start + (i + 1) * Ps]
                if ch.window_m is not None:
                    raw, dp = window_mean(raw, dp)
                pos = np.moveaxis(_cubic(tk, raw, ch.time_s), 0, 1)[..., :k]
                if f0 is not None:
                    pos = pos - pos[:, f0:f0 + 1] + np.asarray(refs[i], float)[:, None, :k]
                pts_sets.append(pos)
                if i == 0:
                    d = {nm: np.moveaxis(_cubic(tk, dp[..., j], ch.time_s), 0, 1)[..., :k]
                         for j, nm in enumerate(col_names)}
                    if f0 is not None:
                        d = {nm: v - v[:, f0:f0 + 1] for nm, v in d.items()}
            for j, p in enumerate(sets["diff"]):
                d[p] = (pts_sets[1 + 2 * j] - pts_sets[2 + 2 * j]) / (2 * SIMILARITY_STEP)
            true[cname] = (pts_sets[0], d)
            start += P
        return true

    def _assemble(self, spec, observations: Observations, results, meta, cls, inst_names) -> Prediction:
        inst_mod = _instrument()
        entries = inst_mod.parse(spec.get("instrument"))
        out: dict[str, dict[str, ChannelPrediction]] = {}
        inputs: dict[str, str] = {}
        for po in observations:
            r = results[po.name]
            tk = r["times"]
            drive_name = meta[po.name]["drive"]
            inputs[po.name] = drive_name
            # the job's derivative columns: FE names then drive parameters
            col_names = r["col_names"]
            true: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]] = {}
            for cname in ("tip_position", "tip_force"):
                if cname == drive_name:
                    ch = po.channels[cname]
                    rec = drive_mod.fill_invalid(ch.values, ch.valid)
                    true[cname] = inst_mod.drive(entries, drive_name, ch.time_s, rec, inst_names)
                    continue
                key, dkey = ("tip_u", "d_tip_u") if cname == "tip_position" else ("tip_f", "d_tip_f")
                if cname not in po.channels:
                    continue
                ch = po.channels[cname]
                vals = _cubic(tk, r[key], ch.time_s)
                d = {nm: _cubic(tk, r[dkey][..., j], ch.time_s) for j, nm in enumerate(col_names)}
                true[cname] = (vals, d)
            true.update(self._points(r, po, meta[po.name], tk, col_names))
            chans: dict[str, ChannelPrediction] = {}
            for cname, (vals, d) in true.items():
                if cname == drive_name:
                    continue
                ch = po.channels[cname]
                mvals, md = inst_mod.measure(entries, cname, ch.time_s, vals, d, true, inst_names)
                mask = None
                if cname == "tip_position" and r["untied"]:
                    mask = np.ones(ch.values.shape, bool)
                    mask[:, r["untied"]] = False
                dd = {}
                for nm, (m, internal) in cls.items():
                    if m == "fd":
                        continue
                    if internal in md:
                        dd[nm] = md[internal]
                    else:
                        dd[nm] = np.zeros_like(mvals)
                chans[cname] = ChannelPrediction(mvals, dd, mask)
            out[po.name] = chans
        return Prediction(out, {}, inputs, {})


__all__ = ["DEFAULT_MAX_STEP", "FEForwardModel", "ProtocolJob", "solve_protocol"]
