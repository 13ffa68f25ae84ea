"""``skinkit lab session``: a session file made by a truth model, and the truth kept apart.

For each protocol of the acquisition library (:mod:`skinkit.acquisition.library`) the
programme drives the truth model — a trajectory by its tip position (FE ``[indenter] mode =
"displacement"``), a force programme by its tip force (``"force"``; motor forces mapped to
the tip through the kinematics at home) — and the truth predicts the other tip channel and,
for a finite-element truth, the tracked surface points. The instruments of
:mod:`skinkit.lab.sensors` then record it: both tip channels at the robot's logging rate
(noise, quantisation, offset), the points at the protocol's camera rate, the undeformed
profile. The session file is laid out like a real one (robot frame records, a track named
after each protocol with its ``noise_m``, the profile ``undeformed``, ``subject =
"virtual"``) and holds nothing about the truth; the truth goes to a separate JSON file.

The truth's surface: flat, or — when the truth fits its top to the session's profile
(``[surface] fit = true`` or ``"auto"``) — a gently curved forearm, a cylinder along x of
radius :data:`SURFACE_RADIUS_M` (0.8 mm lower at 20 mm from the axis: curved, yet the fitted
mesh keeps well-shaped elements under its fixed rim).
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from skinkit import jsonio
from skinkit.errors import SkinkitError
from skinkit.lab.sensors import JACOBIAN_HOME, LOG_RATE_HZ, SensorModel
from skinkit.lab.truth_mesh import DEFAULT_FACTOR as DEFAULT_MESH_FACTOR
from skinkit.lab.truth_mesh import check_mode, describe_meshes, error_figures, mesh_figures, own_mesh
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations, SurfaceProfile

#: Table 12 protocols of a finite-element truth when neither --protocols nor the model's
#: ``[session] protocols`` says otherwise
DEFAULT_FE_PROTOCOLS = ("normal_indentation", "in_plane_000", "in_plane_090", "out_of_plane_330")
#: a lumped truth: its quasi-static test (displacement in, force out), or the stochastic force
#: programme for a dynamic (K-B-I, Wiener) one
DEFAULT_LUMPED_PROTOCOLS = ("normal_indentation",)
DEFAULT_DYNAMIC_PROTOCOLS = ("stochastic_full_scale",)
#: force programmes an FE truth can afford (quasi-static solves at [drive] max_step): the
#: stochastic force low-passed at 0.2 Hz (>= 10 steps per shortest period at 0.5 s steps),
#: 10 mN per motor (30 mN normal, the in vivo model's scale), 30 s, cameras at 1 Hz
FE_FORCE_PARAMETERS: dict[str, Any] = {"force_max": 0.01, "cutoff": 0.2, "setpoint_rate": 100.0,
                                       "duration": 30.0, "camera_rate": 1.0}
#: tracked points: a 1 mm grid from 1 mm outside the indenter's rim out to 8 mm (or 80 % of
#: the model's radius), like the speckle points the thesis tracked around the probe
TRACK_SPACING_M = 1e-3
TRACK_CLEARANCE_M = 1e-3
TRACK_OUTER_M = 8e-3
#: profile: a 1 mm grid over the model's top surface and 2 mm beyond
PROFILE_SPACING_M = 1e-3
PROFILE_MARGIN_M = 2e-3
#: radius [m] of the truth's curved surface (a cylinder along x) when it fits a profile
SURFACE_RADIUS_M = 0.25
#: half-width [m] of the profile of a truth with no mesh (lumped)
LUMPED_PROFILE_HALF_M = 20e-3
#: the profile's per-point quality (peak correlation, as the built-in profiler reports it)
PROFILE_QUALITY = 0.95
#: samples per block appended to a record (as a driver streams them)
BLOCK_SAMPLES = 5000
#: robot frame <-> skin frame (z flips)
FLIP = np.array([1.0, 1.0, -1.0])
TRUTH_FORMAT = "skinkit-lab-truth"

Progress = Callable[[str, float], None]


class LabError(SkinkitError):
    """A bad option or truth for ``skinkit lab session``; the message names it."""


@dataclass
class PlannedProtocol:
    """One protocol of the session before the truth runs.

    Attributes:
        protocol: the library protocol (parameters as run).
        drive: ``"tip_position"`` (a trajectory) or ``"tip_force"`` (a force programme).
        time_s: ``(T,)`` logging times [s] at :data:`LOG_RATE_HZ`.
        drive_robot: ``(T, 3)`` true drive in the robot frame [m or N].
        frames: ``(F,)`` camera frame times [s], empty without cameras.
    """

    protocol: Protocol
    drive: str
    time_s: np.ndarray
    drive_robot: np.ndarray
    frames: np.ndarray


# -- options ---------------------------------------------------------------------------------
def parse_protocols(text: str | Sequence[str] | None) -> list[str] | None:
    """Protocol names from ``"a,b"`` or a list; None when not given; unknown names are an error."""
    from skinkit.acquisition.library import names as known

    if text is None:
        return None
    items = [s.strip() for s in text.split(",")] if isinstance(text, str) else [str(s).strip() for s in text]
    items = [s for s in items if s]
    if not items:
        raise LabError("--protocols: no protocol named")
    unknown = [s for s in items if s not in known()]
    if unknown:
        raise LabError(f"--protocols: unknown protocol(s) {', '.join(unknown)}; known: {', '.join(known())}")
    dup = sorted({s for s in items if items.count(s) > 1})
    if dup:
        raise LabError(f"--protocols: {', '.join(dup)} named twice")
    return items


def check_noise_scale(value: Any) -> float:
    """``value`` as a positive finite float, else a :class:`LabError`."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise LabError(f"--noise-scale: expected a positive number, got {value!r}") from None
    if not (math.isfinite(x) and x > 0):
        raise LabError(f"--noise-scale: must be positive and finite, got {value!r}")
    return x


def _check_out(out: Path, what: str) -> None:
    if out.exists():
        raise LabError(f"{what} {out}: already exists; remove it or choose another path")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise LabError(f"{what} {out}: no such directory {parent}")
    if not os.access(parent, os.W_OK):
        raise LabError(f"{what} {out}: directory {parent} is not writable")


# -- programmes ------------------------------------------------------------------------------
def tip_force_from_motors(motor_forces: np.ndarray) -> np.ndarray:
    """Tip force ``(N, 3)`` [N] (robot frame) of motor forces ``(N, 3)`` [N] at the home pose:
    ``J⁻ᵀ f`` (virtual work; the arms' own dynamics are left out)."""
    return np.asarray(motor_forces, dtype=float) @ np.linalg.inv(JACOBIAN_HOME)


def plan_protocol(name: str, parameters: Mapping[str, Any] | None = None) -> PlannedProtocol:
    """The library protocol ``name`` with ``parameters`` overriding its defaults: the true
    drive at the logging rate (the robot follows its setpoints, linearly interpolated as the
    device does) and the camera frame times."""
    from skinkit.acquisition.library import ProtocolError, make_protocol, programme

    try:
        proto = make_protocol(name, **dict(parameters or {}))
        prog = programme(proto)
    except ProtocolError as exc:
        raise LabError(str(exc)) from None
    n = int(round(prog.duration_s * LOG_RATE_HZ)) + 1
    t = np.arange(n) / LOG_RATE_HZ
    sp = prog.setpoints if prog.kind == "trajectory" else tip_force_from_motors(prog.setpoints)
    drive = np.stack([np.interp(t, prog.time_s, sp[:, j]) for j in range(3)], axis=1)
    frames = np.zeros(0)
    if prog.camera_rate_hz > 0:
        nf = int(math.floor(prog.duration_s * prog.camera_rate_hz + 1e-9)) + 1
        frames = np.round(np.arange(nf) / prog.camera_rate_hz * LOG_RATE_HZ) / LOG_RATE_HZ
    return PlannedProtocol(proto, "tip_position" if prog.kind == "trajectory" else "tip_force", t, drive,
                           frames)


# -- the truth's surface, points and profile ----------------------------------------------------
def surface_height(xy: np.ndarray, curved: bool) -> np.ndarray:
    """Height ``(N,)`` [m] of the truth's undeformed top surface at ``xy`` ``(N, 2)`` [m]."""
    y = np.asarray(xy, dtype=float)[:, 1]
    if not curved:
        return np.zeros(len(y))
    R = SURFACE_RADIUS_M
    return np.sqrt(np.maximum(R * R - y * y, 0.0)) - R


@dataclass
class TopSurface:
    """Where the truth's top surface is: its extent, the indenter's radius, its shape."""

    half_x: float
    half_y: float
    indenter_radius: float
    curved: bool
    has_mesh: bool
    #: rigid regions away from the origin (two-pad geometry's pads): (xmin, xmax, ymin, ymax) [m]
    exclude: tuple[tuple[float, float, float, float], ...] = ()

    def track_reference(self) -> np.ndarray:
        """``(P, 3)`` [m] tracked material points on the undeformed surface (skin frame)."""
        r_in = self.indenter_radius + TRACK_CLEARANCE_M
        r_out = min(TRACK_OUTER_M, 0.8 * min(self.half_x, self.half_y))
        k = int(math.floor(r_out / TRACK_SPACING_M + 1e-9))
        g = np.arange(-k, k + 1) * TRACK_SPACING_M
        X, Y = np.meshgrid(g, g, indexing="ij")
        xy = np.column_stack([X.ravel(), Y.ravel()])
        r = np.hypot(xy[:, 0], xy[:, 1])
        keep = (r >= r_in - 1e-12) & (r <= r_out + 1e-12)
        for x0, x1, y0, y1 in self.exclude:   # points clear of the pads
            c = TRACK_CLEARANCE_M
            keep &= ~((xy[:, 0] > x0 - c) & (xy[:, 0] < x1 + c) & (xy[:, 1] > y0 - c) & (xy[:, 1] < y1 + c))
        xy = xy[keep]
        return np.column_stack([xy, surface_height(xy, self.curved)])

    def profile_points(self) -> np.ndarray:
        """``(N, 3)`` [m] true points of the undeformed surface the profiler sees."""
        gx = np.arange(-self.half_x - PROFILE_MARGIN_M, self.half_x + PROFILE_MARGIN_M + 1e-12,
                       PROFILE_SPACING_M)
        gy = np.arange(-self.half_y - PROFILE_MARGIN_M, self.half_y + PROFILE_MARGIN_M + 1e-12,
                       PROFILE_SPACING_M)
        X, Y = np.meshgrid(gx, gy, indexing="ij")
        xy = np.column_stack([X.ravel(), Y.ravel()])
        return np.column_stack([xy, surface_height(xy, self.curved)])


def top_surface(spec: Mapping[str, Any] | None, kind: str) -> TopSurface:
    """The top surface of a truth description (an FE mesh's extent; a lumped truth has none)."""
    if kind != "fe" or spec is None:
        h = LUMPED_PROFILE_HALF_M
        return TopSurface(h, h, 0.0, False, False)
    from skinkit.fem.model import build_mesh

    mesh = build_mesh(dict(spec))
    top = mesh.nodes[mesh.node_sets["top"]]
    ind = mesh.node_sets.get("indenter")
    r_ind = float(np.hypot(*mesh.nodes[ind, :2].T).max()) if ind is not None and len(ind) else 0.0
    exclude = []
    if ind is not None and len(ind):
        lo, hi = mesh.nodes[ind, :2].min(axis=0), mesh.nodes[ind, :2].max(axis=0)
        if not (lo[0] <= 0 <= hi[0] and lo[1] <= 0 <= hi[1]):   # a pad beside the origin, not a probe on it
            r_ind = 0.0
            for s in ("indenter", "pad_fixed"):
                if s in mesh.node_sets:
                    xy_s = mesh.nodes[mesh.node_sets[s], :2]
                    a, b = xy_s.min(axis=0), xy_s.max(axis=0)
                    exclude.append((float(a[0]), float(b[0]), float(a[1]), float(b[1])))
    fit = dict(spec.get("surface", {}) or {}).get("fit", "auto")
    return TopSurface(float(np.abs(top[:, 0]).max()), float(np.abs(top[:, 1]).max()), r_ind,
                      fit in (True, "auto"), True, tuple(exclude))


# -- the skeleton a truth predicts -------------------------------------------------------------
def skeleton(planned: Sequence[PlannedProtocol], sensors: SensorModel, reference: np.ndarray | None,
             profile: SurfaceProfile | None) -> Observations:
    """Observations the truth is asked to predict: per protocol its drive (the true
    programme, skin frame), the other tip channel and the points (placeholders) on exactly
    the times and points the session will record."""
    protos: dict[str, ProtocolObservations] = {}
    for p in planned:
        chans: dict[str, Channel] = {}
        for c in ("tip_position", "tip_force"):
            v = p.drive_robot * FLIP if c == p.drive else np.zeros_like(p.drive_robot)
            chans[c] = Channel(c, p.time_s, v, noise=sensors.sigma(c))
        if reference is not None and p.frames.size:
            vals = np.repeat(reference[:, None, :], p.frames.size, axis=1)
            chans["points"] = Channel("points", p.frames, vals, noise=sensors.sigma("points"),
                                      reference=reference)
        protos[p.protocol.name] = ProtocolObservations(p.protocol, chans)
    return Observations(protos, profile, "virtual lab")


def _default_protocols(spec: Mapping[str, Any], kind: str, model: Any) -> list[str]:
    listed = dict(spec.get("session", {}) or {}).get("protocols")
    if listed:
        return list(parse_protocols([str(s) for s in listed]) or [])
    if kind == "fe":
        return list(DEFAULT_FE_PROTOCOLS)
    own = getattr(model, "default_protocols", None)
    if own:
        return list(own)
    words = jsonio.dumps(spec.get("lumped", {}), default=str).lower()
    if any(w in words for w in ("kbi", "k-b-i", "wiener", "dynamic", "inertia")):
        return list(DEFAULT_DYNAMIC_PROTOCOLS)
    return list(DEFAULT_LUMPED_PROTOCOLS)


def _protocol_parameters(spec: Mapping[str, Any], kind: str, name: str) -> dict[str, Any]:
    from skinkit.acquisition.library import make_protocol

    out: dict[str, Any] = {}
    if kind == "fe" and make_protocol(name).kind == "force":
        out.update(FE_FORCE_PARAMETERS)
    table = dict(dict(spec.get("session", {}) or {}).get("parameters", {}) or {})
    out.update(dict(table.get(name, {}) or {}))
    return out


# -- running the truth -------------------------------------------------------------------------
def _load(spec: Mapping[str, Any], workers: int | None) -> Any:
    from skinkit.forward import load

    return load(spec, workers=workers)


def _predict_group(model: Any, obs: Observations, drive: dict[str, str]) -> dict[str, dict[str, np.ndarray]]:
    """Noiseless truth per protocol and channel (skin frame) from ``model``'s prediction."""
    pred = model.predict(model.parameters(), obs)
    out: dict[str, dict[str, np.ndarray]] = {}
    for po in obs:
        used = pred.inputs.get(po.name, drive[po.name])
        if used != drive[po.name]:
            raise LabError(f"truth model {getattr(model, 'name', '?')!r} is driven by {used} but protocol "
                           f"{po.name!r} drives {drive[po.name]}; choose protocols of the model's test "
                           "(--protocols)")
        chans = pred.protocols.get(po.name, {})
        got: dict[str, np.ndarray] = {drive[po.name]: po.channels[drive[po.name]].values}
        for c in po.channels:
            if c == drive[po.name]:
                continue
            if c not in chans:
                raise LabError(f"truth model {getattr(model, 'name', '?')!r} does not predict {c} of "
                               f"protocol {po.name!r}")
            got[c] = np.nan_to_num(np.asarray(chans[c].values, dtype=float))
        out[po.name] = got
    return out


def run_truth(truth: Any, planned: Sequence[PlannedProtocol], sensors: SensorModel,
              surface: TopSurface, workers: int | None = None,
              progress: Progress | None = None, points: np.ndarray | None = None,
              stage: str = "truth model") -> tuple[dict[str, dict[str, np.ndarray]], Any]:
    """The noiseless channels ``{protocol: {channel: values (skin frame)}}`` of ``truth`` (a
    model description, or an already built forward model) and a model for its parameters.
    ``points`` ``(P, 3)`` [m]: the material points to follow (default: the tracked grid).
    ``progress(stage, fraction)``: advanced by the solves as they go."""
    from skinkit.forward.stages import feeding

    is_model = hasattr(truth, "predict")
    kind = str(getattr(truth, "kind", "fe")) if is_model else _kind(truth)
    reference = surface.track_reference() if (kind == "fe" and surface.has_mesh) else None
    if points is not None and reference is not None:
        reference = np.asarray(points, dtype=float)
    profile = None
    if surface.curved:
        pts = surface.profile_points()
        profile = SurfaceProfile(pts, np.ones(len(pts)))
    groups: dict[str, list[PlannedProtocol]] = {}
    for p in planned:
        groups.setdefault(p.drive if kind == "fe" and not is_model else "all", []).append(p)
    results: dict[str, dict[str, np.ndarray]] = {}
    first = None
    for i, (key, group) in enumerate(groups.items()):
        if progress:
            progress(stage, i / len(groups))
        if is_model:
            model = truth
        else:
            spec = copy.deepcopy(dict(truth))
            if kind == "fe":
                spec.setdefault("indenter", {})["mode"] = "displacement" if key == "tip_position" else "force"
            model = _load(spec, workers)
        try:
            obs = skeleton(group, sensors, reference, profile)
            with feeding(progress, stage, i / len(groups), (i + 1) / len(groups)):
                results.update(_predict_group(model, obs, {p.protocol.name: p.drive for p in group}))
        except BaseException:
            for m in {id(x): x for x in (model, first) if x is not None and x is not truth}.values():
                m.close()
            raise
        if first is None:
            first = model
        elif model is not truth:
            model.close()
    if progress:
        progress(stage, 1.0)
    return results, first


def _kind(spec: Mapping[str, Any]) -> str:
    from skinkit.forward import model_kind

    return model_kind(spec)


# -- writing ---------------------------------------------------------------------------------
def _json_ready(obj: Any) -> Any:
    if isinstance(obj, Mapping):
        return {str(k): _json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_ready(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _json_ready(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return str(obj)
    if obj is None or isinstance(obj, (str, int, float, bool)):
        return obj
    return str(obj)


def _write_session(path: Path, planned: Sequence[PlannedProtocol], recorded: dict[str, dict[str, Any]],
                   profile: SurfaceProfile | None, track_noise: Sequence[float] | None,
                   progress: Progress | None, operator: str = "skinkit lab", dimensions: int = 3) -> None:
    from skinkit.schemas import RobotRecord, SurfaceTrack
    from skinkit.schemas.robot import FLAG_CAMERA_TRIGGER
    from skinkit.store import create_experiment

    with create_experiment(path) as exp:
        exp.set_metadata(subject="virtual", site="forearm (virtual lab)", operator=operator)
        for i, p in enumerate(planned):
            if progress:
                progress("write session", i / len(planned))
            rec = recorded[p.protocol.name]
            flags = np.zeros(p.time_s.size, dtype=np.uint32)
            if p.frames.size:
                flags[np.round(p.frames * LOG_RATE_HZ).astype(int)] |= FLAG_CAMERA_TRIGGER
            with exp.record_writer(p.protocol, ("tip_position", "tip_force"), rate_hz=LOG_RATE_HZ) as w:
                for a in range(0, p.time_s.size, BLOCK_SAMPLES):
                    b = min(a + BLOCK_SAMPLES, p.time_s.size)
                    w.append(RobotRecord(time_s=p.time_s[a:b], tip_position=rec["tip_position"][a:b],
                                         tip_force=rec["tip_force"][a:b], flags=flags[a:b],
                                         protocol=p.protocol))
            exp.set_record_attrs(p.protocol.name, session_index=i)
            if "points" in rec and track_noise is not None:
                pts = rec["points"]
                exp.write_track(p.protocol.name, SurfaceTrack(pts, np.ones(pts.shape[:2], bool), p.frames))
                exp.set_track_attrs(p.protocol.name, noise_m=[float(v) for v in track_noise],
                                    dimensions=dimensions)
        if profile is not None:
            exp.write_profile("undeformed", profile)


def write_records(vs: VirtualSession, out: str | os.PathLike[str], operator: str,
                  progress: Progress | None = None) -> None:
    """Write only the robot records of ``vs`` into a new experiment file ``out`` (no tracks, no
    profile: a caller that images the session measures those itself)."""
    _write_session(Path(out), vs.planned, vs.recorded, None, None, progress, operator)


@dataclass
class VirtualSession:
    """A generated session in memory: what the truth did and what the instruments recorded.

    Attributes:
        planned: the protocols, in session order.
        noiseless: protocol -> channel -> true values (skin frame; tip ``(T, 3)``, points ``(P, F, 3)``).
        recorded: protocol -> channel -> recorded values (tip channels in the robot frame).
        profile_true, profile: ``(N, 3)`` true and profiled undeformed surface points [m].
        sensors: the instrument model.
        truth: the truth document (JSON-ready) the truth file holds.
    """

    planned: list[PlannedProtocol]
    noiseless: dict[str, dict[str, np.ndarray]]
    recorded: dict[str, dict[str, np.ndarray]]
    profile_true: np.ndarray
    profile: np.ndarray
    sensors: SensorModel
    truth: dict[str, Any]


def _record(planned: Sequence[PlannedProtocol], noiseless: Mapping[str, Mapping[str, np.ndarray]],
            profile_true: np.ndarray, sensors: SensorModel, seed: int
            ) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, Any], np.ndarray]:
    """The instruments' readings; every protocol draws from its own stream of ``seed`` (so
    adding a protocol does not change the others' noise)."""
    recorded: dict[str, dict[str, np.ndarray]] = {}
    offsets: dict[str, Any] = {}
    for i, p in enumerate(planned):
        name = p.protocol.name
        true = noiseless[name]
        rng = np.random.default_rng([int(seed), i])
        off = {c: sensors.offset(c, rng) for c in ("tip_position", "tip_force")}
        offsets[name] = {c: {"robot_frame": v.tolist(), "skin_frame": (v * FLIP).tolist()}
                         for c, v in off.items()}
        rec = {"tip_position": sensors.measure_position(true["tip_position"] * FLIP, off["tip_position"],
                                                        rng),
               "tip_force": sensors.measure_force(true["tip_force"] * FLIP, off["tip_force"], rng)}
        if "points" in true:
            rec["points"] = sensors.measure_points(true["points"], rng)
        recorded[name] = rec
    profile = sensors.measure_profile(profile_true, np.random.default_rng([int(seed), len(planned)]))
    return recorded, offsets, profile


def simulate(truth: str | os.PathLike[str] | Mapping[str, Any] | Any, seed: int,
             protocols: str | Sequence[str] | None = None, noise_scale: float = 1.0,
             progress: Progress | None = None, workers: int | None = None,
             points: np.ndarray | None = None, mesh: str = "own",
             mesh_factor: int | None = None, sensors: SensorModel | None = None) -> VirtualSession:
    """Run ``truth`` through the protocols and record it (see :func:`make_session`); nothing is
    written. ``points`` ``(P, 3)`` [m]: material points of the top surface to follow instead of
    the tracked grid (e.g. a dense grid from which camera views are rendered). ``mesh``: a
    finite-element truth description is solved on a mesh of its own, ``mesh_factor`` times finer
    with its own node placement (``"own"``, :mod:`skinkit.lab.truth_mesh`; default 2), on three
    of its own extrapolated to a vanishing element size, the finest ``mesh_factor`` times the
    model's counts (``"extrapolated"``, :mod:`skinkit.lab.truth_extrapolation`; default 3), or
    on the mesh its description gives, the model's (``"shared"``). ``sensors``: the instruments
    (default: the robot's, :class:`SensorModel` at ``noise_scale``; when given, ``noise_scale``
    is its own)."""
    if mesh_factor is None:
        mesh_factor = 3 if mesh == "extrapolated" else DEFAULT_MESH_FACTOR
    check_mode(mesh, mesh_factor)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise LabError(f"--seed: expected a non-negative integer, got {seed!r}")
    if sensors is None:
        sensors = SensorModel(check_noise_scale(noise_scale))
    names = parse_protocols(protocols)
    is_model = hasattr(truth, "predict")
    if is_model:
        spec: dict[str, Any] = dict(getattr(truth, "spec", {}) or {})
        kind = str(getattr(truth, "kind", "fe"))
        source = str(getattr(truth, "name", "model"))
    else:
        from skinkit.forward import read_description

        spec = read_description(truth)
        kind = _kind(spec)
        source = str(truth) if not isinstance(truth, Mapping) else "<description>"
    if names is None:
        names = _default_protocols(spec, kind, truth if is_model else None)
    planned = [plan_protocol(n, _protocol_parameters(spec, kind, n)) for n in names]
    surface = top_surface(spec if not is_model else None, kind)
    mesh_doc: dict[str, Any] | None = None
    if kind == "fe" and not is_model:
        noiseless, model, mesh_doc = _truth_on_meshes(spec, mesh, mesh_factor, planned, sensors, surface,
                                                      workers, progress, points)
    else:
        noiseless, model = run_truth(truth if is_model else spec, planned, sensors, surface, workers,
                                     progress, points)
    try:
        description = _description(model, spec, kind)
        parameters = model.parameters().to_list()
    finally:
        if model is not truth:
            model.close()
    profile_true = surface.profile_points()
    recorded, offsets, profile = _record(planned, noiseless, profile_true, sensors, int(seed))
    truth_doc = {
        "format": TRUTH_FORMAT, "version": 1, "session_file": None, "source": source, "kind": kind,
        "model_file": _json_ready(spec),
        "model": _json_ready(description),
        "effects": _json_ready(spec.get("effects", []) or []),
        "parameters": _json_ready(parameters),
        "seed": int(seed), "noise_scale": sensors.scale, "sensors": sensors.to_dict(),
        "offsets": _json_ready(offsets),
        "mesh": mesh_doc,
        "surface": {"curved": surface.curved, "radius_m": SURFACE_RADIUS_M if surface.curved else None,
                    "axis": "x"},
        "protocols": [{"name": p.protocol.name, "kind": p.protocol.kind, "drive": p.drive,
                       "parameters": _json_ready(p.protocol.parameters), "duration_s": p.protocol.duration_s,
                       "samples": int(p.time_s.size), "frames": int(p.frames.size),
                       "points": int(noiseless[p.protocol.name]["points"].shape[0])
                       if "points" in noiseless[p.protocol.name] else 0} for p in planned],
    }
    return VirtualSession(planned, noiseless, recorded, profile_true, profile, sensors, truth_doc)


def _noise_levels(sensors: SensorModel) -> dict[str, float]:
    return {c: float(np.sqrt(np.mean(np.square(sensors.sigma(c)))))
            for c in ("tip_force", "tip_position", "points")}


def _truth_on_meshes(spec: dict[str, Any], mesh: str, factor: int, planned: Sequence[PlannedProtocol],
                     sensors: SensorModel, surface: TopSurface, workers: int | None,
                     progress: Progress | None, points: np.ndarray | None
                     ) -> tuple[dict[str, dict[str, np.ndarray]], Any, dict[str, Any]]:
    """A finite-element description's noiseless truth, the model it was solved with and the truth
    file's ``mesh`` entry: on the model's mesh, on one of its own, or extrapolated from three of
    its own (:mod:`skinkit.lab.truth_extrapolation`); the last two with the truth's own error and the
    model mesh's (the same truth solved on the model's mesh) against the noise."""
    if mesh == "shared":
        noiseless, model = run_truth(spec, planned, sensors, surface, workers, progress, points)
        return noiseless, model, describe_meshes(spec, spec, mesh, factor)
    opened: list[Any] = []
    try:
        if mesh == "extrapolated":
            from skinkit.lab.truth_extrapolation import extrapolate, members
            from skinkit.lab.truth_mesh import own_gradings

            ks = members(factor)
            solved, unknowns = {}, []
            for k in ks:
                member = own_gradings(spec, k)
                solved[k], m = run_truth(member, planned, sensors, surface, workers, progress, points,
                                         stage=f"truth, mesh {k}x of {ks[-1]}x")
                opened.append(m)
                unknowns.append(mesh_figures(member)["unknowns"])
            noiseless, rep = extrapolate(solved, ks, _noise_levels(sensors))
            finest = own_gradings(spec, ks[-1])
        else:
            finest = own_mesh(spec, factor)
            noiseless, m = run_truth(finest, planned, sensors, surface, workers, progress, points)
            opened.append(m)
        coarse, other = run_truth(spec, planned, sensors, surface, workers, progress, points,
                                  stage="truth on the model's mesh")
        other.close()
    except BaseException:
        for m in opened:
            m.close()
        raise
    model = opened.pop()
    for m in opened:
        m.close()
    doc = describe_meshes(finest, spec, mesh, factor)
    figures = error_figures(noiseless, coarse, _noise_levels(sensors), factor)
    if mesh == "extrapolated":
        # the model mesh's error is the whole difference from the limit; the truth's is estimated
        for c, row in figures.items():
            row["model_rms"] = row["truth_rms"] * (factor - 1)
            row["model_over_noise"] = row["model_rms"] / row["noise"] if row["noise"] else None
            est = rep["channels"].get(c, {})
            row.update(est)
        doc["extrapolation"] = {"members": rep["members"], "member_unknowns": unknowns,
                                "orders": rep["orders"]}
    doc["discretisation"] = figures
    return noiseless, model, doc


def resample(vs: VirtualSession, seed: int) -> VirtualSession:
    """The same truth recorded again with the noise of ``seed`` (no model run)."""
    recorded, offsets, profile = _record(vs.planned, vs.noiseless, vs.profile_true, vs.sensors, int(seed))
    truth = copy.deepcopy(vs.truth)
    truth.update(seed=int(seed), offsets=_json_ready(offsets))
    return VirtualSession(vs.planned, vs.noiseless, recorded, vs.profile_true, profile, vs.sensors, truth)


def write_session(vs: VirtualSession, out: str | os.PathLike[str], truth_out: str | os.PathLike[str],
                  progress: Progress | None = None) -> dict[str, Any]:
    """Write the session file ``out`` and the truth file ``truth_out``, both or neither
    (written to temporary files, renamed on success). Returns the truth document."""
    out, truth_out = Path(out), Path(truth_out)
    _check_paths(out, truth_out)
    doc = dict(vs.truth, session_file=str(out))
    profile = SurfaceProfile(vs.profile, np.full(len(vs.profile), PROFILE_QUALITY))
    tmp_h5 = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    tmp_js = truth_out.with_name(f".{truth_out.name}.{os.getpid()}.tmp")
    done: list[Path] = []
    try:
        _write_session(tmp_h5, vs.planned, vs.recorded, profile, vs.sensors.track_noise_m(), progress,
                       dimensions=vs.sensors.track_dimensions)
        tmp_js.write_text(jsonio.dumps(doc, indent=1, allow_nan=False) + "\n")
        os.replace(tmp_h5, out)
        done.append(out)
        os.replace(tmp_js, truth_out)
    except BaseException:
        for t in (tmp_h5, tmp_js, *done):
            if t.exists():
                t.unlink()
        raise
    if progress:
        progress("write session", 1.0)
    return doc


def _check_paths(out: Path, truth_out: Path) -> None:
    if out.resolve() == truth_out.resolve():
        raise LabError(f"--truth-out {truth_out}: must differ from --out (the truth is kept apart)")
    _check_out(out, "--out")
    _check_out(truth_out, "--truth-out")


def check_options(out: str | os.PathLike[str], truth_out: str | os.PathLike[str],
                  protocols: str | Sequence[str] | None = None, noise_scale: Any = 1.0,
                  images: bool = False) -> None:
    """Every option of :func:`make_session` that can be checked before the truth runs; a
    one-line :class:`LabError` naming the first bad one."""
    if images:
        raise LabError("--images: rendering the four cameras through calibrate, profile and track is not "
                       "available yet; run without --images for the fast tracking model")
    check_noise_scale(noise_scale)
    parse_protocols(protocols)
    _check_paths(Path(out), Path(truth_out))


def make_session(truth: str | os.PathLike[str] | Mapping[str, Any] | Any, out: str | os.PathLike[str],
                 truth_out: str | os.PathLike[str], seed: int, protocols: str | Sequence[str] | None = None,
                 noise_scale: float = 1.0, images: bool = False, progress: Progress | None = None,
                 workers: int | None = None, mesh: str = "own") -> dict[str, Any]:
    """Generate a virtual session ``out`` (experiment file) and its truth ``truth_out`` (JSON).

    ``truth``: a model file, a parsed description, or a built forward model (duck-typed:
    ``name``, ``kind``, ``parameters()``, ``predict``, optional ``spec``). ``seed`` (>= 0):
    every random draw (noise, offsets) follows from it. ``protocols``: library names
    (``"a,b"`` or a list; default: the model's ``[session] protocols``, else the kind's
    default). ``noise_scale`` (> 0) multiplies every imperfection of the instruments.
    ``progress(stage, fraction)``; ``workers``: the FE truth's worker processes; ``mesh``: a
    finite-element truth on a mesh of its own (``"own"``), extrapolated from three of its own
    (``"extrapolated"``) or on the model's (``"shared"``; see :func:`simulate`). Options are
    checked before any model runs; nothing is left at ``out`` or ``truth_out`` on failure.
    Returns the truth document.
    """
    check_options(out, truth_out, protocols, noise_scale, images)
    vs = simulate(truth, seed, protocols, noise_scale, progress, workers, mesh=mesh)
    return write_session(vs, out, truth_out, progress)


def _description(model: Any, spec: Mapping[str, Any], kind: str) -> Any:
    """The truth's description after its effects (FE: with the file's own indenter mode)."""
    fn = getattr(model, "description", None)
    if not callable(fn):
        return spec
    desc = copy.deepcopy(fn(model.parameters()))
    if kind == "fe":
        mode = dict(spec.get("indenter", {}) or {}).get("mode")
        if mode is None:
            desc.get("indenter", {}).pop("mode", None)
        else:
            desc.setdefault("indenter", {})["mode"] = mode
    return desc


__all__ = ["DEFAULT_FE_PROTOCOLS", "FE_FORCE_PARAMETERS", "LabError", "PlannedProtocol", "SensorModel",
           "TopSurface", "VirtualSession", "check_noise_scale", "check_options", "make_session",
           "parse_protocols", "plan_protocol", "resample", "run_truth", "simulate", "skeleton",
           "surface_height", "tip_force_from_motors", "top_surface", "write_records", "write_session"]
