"""A finite-element model file as an FEBio model (``.feb``, FEBio spec 4.0).

``febio_model(MODEL_FILE, session=..., protocol=...)`` builds the XML tree; ``write_feb``
writes it. The file holds the mesh as 27-node hexahedra (``hex27``, FEBio's node order), one
material per layer (:mod:`skinkit.export.febio_materials`), the fixed node sets, the rigid
indenter (or moving pad) as a rigid body tied to its nodes, and the load curves that drive it:
the model file's ``[load]`` programme, or with a session the recorded drive of one protocol
(and the other recorded tip channel, for comparison). Units are mm, N, s and MPa; skinkit's
SI values are converted. What FEBio has no exact counterpart of is refused with
:class:`UnsupportedFeature` naming it. The mapping is documented in
``docs/reference/febio-export.md``.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError
from skinkit.export.febio_materials import UnsupportedFeature, add_param, fmt, material_element

__all__ = ["FEBIO_HEX27_RST", "FEBIO_SPEC_VERSION", "M_TO_MM", "UNITS", "Curve", "UnsupportedFeature",
           "febio_model", "hex27_connectivity", "write_feb"]

#: the FEBio input-file version written (``<febio_spec version="4.0">``)
FEBIO_SPEC_VERSION = "4.0"
#: unit system of the file
UNITS = "mm, N, s, MPa"
#: m -> mm
M_TO_MM = 1e3
#: FEBio's hex27 node order: the natural coordinates (r, s, t) of local nodes 1..27 (FEBio's
#: ``FEHex27`` shape functions): corners, bottom edges, top edges, vertical edges, side-face
#: centres (s-, r+, s+, r-), bottom and top face centres, the centre
FEBIO_HEX27_RST = np.array(
    [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1), (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1),
     (0, -1, -1), (1, 0, -1), (0, 1, -1), (-1, 0, -1), (0, -1, 1), (1, 0, 1), (0, 1, 1), (-1, 0, 1),
     (-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0), (0, -1, 0), (1, 0, 0), (0, 1, 0), (-1, 0, 0),
     (0, 0, -1), (0, 0, 1), (0, 0, 0)], dtype=float)
#: the rigid body's own element: a box this fraction of the tied region's width tall
_PROBE_HEIGHT = 0.25


@dataclass
class Curve:
    """A load curve: ``times`` ``(n,)`` [s] and ``values`` ``(n,)`` in the file's units."""

    name: str
    times: np.ndarray
    values: np.ndarray


@dataclass
class Drive:
    """How the indenter is driven: ``mode`` ("displacement" or "force"), one curve per tied
    component (``curves[c]``), recorded curves kept for comparison, and the time stepping."""

    mode: str
    curves: dict[int, Curve]
    n_steps: int
    duration: float
    measured: list[Curve] = field(default_factory=list)
    source: str = ""


def _skfem_hex2_order(swap: bool) -> np.ndarray:
    """``(27,)`` local dof of scikit-fem's ``ElementHex2`` at each FEBio hex27 node; ``swap``
    exchanges r and s (the mirror image, for an element whose reference frame is left-handed)."""
    from skfem import ElementHex2

    loc = ElementHex2().doflocs                     # (27, 3) reference positions in [0, 1]^3
    rst = FEBIO_HEX27_RST[:, [1, 0, 2]] if swap else FEBIO_HEX27_RST
    out = [np.flatnonzero(np.all(np.isclose(loc, (r + 1) / 2), axis=1)) for r in rst]
    return np.array([int(k[0]) for k in out])


def hex27_connectivity(nodes: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """``(E, 27)`` node indices of ``elements`` ``(E, 27)`` (scikit-fem order) in FEBio's hex27
    order, each element oriented so that its Jacobian is positive (r, s, t right-handed);
    ``nodes`` ``(N, 3)``."""
    out = elements[:, _skfem_hex2_order(False)]
    corners = nodes[out[:, :8]]                          # (E, 8, 3)
    # dx/d(r, s, t) at the centre of the trilinear map of the corners
    d = np.einsum("eai,ak->eik", corners, FEBIO_HEX27_RST[:8]) / 8.0
    left = np.linalg.det(d) < 0
    out[left] = elements[left][:, _skfem_hex2_order(True)]
    return out


def gauss_jacobians(x: np.ndarray) -> np.ndarray:
    """``(E, 27)`` Jacobian determinants of hex27 elements with node positions ``x`` ``(E, 27, 3)``
    (FEBio order) at the 3x3x3 Gauss points FEBio integrates them with."""
    g = math.sqrt(0.6)
    out = []
    for r, s, t in ((a, b, c) for a in (-g, 0.0, g) for b in (-g, 0.0, g) for c in (-g, 0.0, g)):
        # 1-D quadratic shape functions and derivatives at -1, +1, 0, per natural coordinate
        vals = [np.array([0.5 * q * (q - 1), 0.5 * q * (q + 1), 1 - q * q]) for q in (r, s, t)]
        ders = [np.array([q - 0.5, q + 0.5, -2 * q]) for q in (r, s, t)]
        idx = np.where(FEBIO_HEX27_RST == -1, 0, np.where(FEBIO_HEX27_RST == 1, 1, 2)).astype(int)
        V = [vals[k][idx[:, k]] for k in range(3)]
        D = [ders[k][idx[:, k]] for k in range(3)]
        dN = np.stack([D[0] * V[1] * V[2], V[0] * D[1] * V[2], V[0] * V[1] * D[2]], axis=1)  # (27, 3)
        out.append(np.linalg.det(np.einsum("eai,ak->eik", x, dN)))
    return np.stack(out, axis=1)


def _build(spec: dict[str, Any], session: str | os.PathLike | None, protocol: str | None):
    """The built :class:`skinkit.fem.model.Model` and its :class:`Drive`."""
    from skinkit.fem.model import build_model

    if session is None:
        model = build_model(spec)
        return model, _programme_drive(model)
    from skinkit.forward.fe import DEFAULT_MAX_STEP, FEForwardModel
    from skinkit.forward.observations import read_observations

    obs = read_observations(session, protocols=[protocol] if protocol else None)
    if protocol is None and len(obs.names) > 1:
        raise SkinkitError(f"--session {session}: holds {len(obs.names)} protocols "
                           f"({', '.join(obs.names)}); choose one with --protocol")
    po = next(iter(obs))
    fm = FEForwardModel(spec, [], workers=1)
    try:
        mesh, _, _ = fm._surface(fm.base, obs)      # fitted to the session's profile when asked
    finally:
        fm.close()
    model = build_model(fm.base, require_load=False, mesh=mesh)
    from skinkit.fem.model import quantity

    max_step = quantity(dict(spec.get("drive", {}) or {}).get("max_step", DEFAULT_MAX_STEP), "s",
                        "drive.max_step")
    return model, _session_drive(model, po, max_step, str(session))


def _programme_drive(model: Any) -> Drive | None:
    """The model file's ``[load]`` programme as load curves (a point per solution step)."""
    rig = model.bc.rigid
    if rig is None:
        return None
    if not model.load.viscous_time and any(m.prony() is not None for m in model.problem.materials):
        raise UnsupportedFeature("[load] without duration around a viscoelastic law", "skinkit "
                                 "takes the instantaneous response of a static load ramp, which "
                                 "FEBio's time-based viscoelastic material has no counterpart of; "
                                 "give [load] duration (seconds)")
    t = np.concatenate([[0.0], np.asarray(model.load.times, dtype=float)])
    vals = np.array([np.asarray(model.load.value(x), dtype=float) for x in t])
    scale = M_TO_MM if rig.mode == "displacement" else 1.0
    axes = "xyz"
    curves = {c: Curve(f"{rig.mode}_{axes[c]}", t, vals[:, c] * scale) for c in rig.components}
    return Drive(rig.mode, curves, len(t) - 1, float(t[-1]), [], model.load.description)


def _channel_curves(ch: Any, scale: float, label: str) -> list[Curve]:
    ok = np.all(np.asarray(ch.valid).reshape(len(ch.time_s), -1), axis=1)
    t = np.asarray(ch.time_s, dtype=float)[ok]
    v = np.asarray(ch.values, dtype=float)[ok]
    return [Curve(f"{label}_{'xyz'[c]}", t, v[:, c] * scale) for c in range(3)]


def _session_drive(model: Any, po: Any, max_step: float, source: str) -> Drive:
    """The recorded drive of protocol ``po`` (valid samples only) as load curves, and the
    other recorded tip channel as curves kept for comparison."""
    rig = model.bc.rigid
    if rig is None:
        raise SkinkitError("[indenter]: a session drives the indenter, and the model has none")
    drive = "tip_force" if rig.mode == "force" else "tip_position"
    other = "tip_position" if drive == "tip_force" else "tip_force"
    if drive not in po.channels:
        raise SkinkitError(f"session protocol {po.name!r}: has no {drive!r} channel to drive the "
                           f"indenter ([indenter] mode = {rig.mode!r}); it has {sorted(po.channels)}")
    scale = {"tip_position": M_TO_MM, "tip_force": 1.0}
    curves = _channel_curves(po.channels[drive], scale[drive], f"recorded_{drive}")
    if len(curves[0].times) < 2:
        raise SkinkitError(f"session protocol {po.name!r}: fewer than two valid {drive!r} samples")
    measured = _channel_curves(po.channels[other], scale[other], f"recorded_{other}") \
        if other in po.channels else []
    duration = float(curves[0].times[-1])
    n = max(1, math.ceil(duration / max_step - 1e-9))
    return Drive(rig.mode, {c: curves[c] for c in rig.components}, n, duration, measured,
                 f"{source}, protocol {po.name}")


def check_supported(spec: dict[str, Any], drive_channel: str) -> None:
    """Refuse what a model file may hold that has no FEBio counterpart, naming it."""
    if spec.get("effects"):
        names = [str(t.get("name")) for t in spec["effects"] if isinstance(t, dict)]
        raise UnsupportedFeature(f"[[effects]] {', '.join(names)}", "candidate effects are not "
                                 "exported; write their result into the model file's laws first")
    if spec.get("fields"):
        names = [str(t.get("name")) for t in spec["fields"] if isinstance(t, dict)]
        raise UnsupportedFeature(f"[[fields]] {', '.join(names)}", "spatial fields on a layer's "
                                 "response have no export (FEBio would need mapped parameters)")
    for i, e in enumerate(spec.get("instrument") or []):
        kind, channel = str(e.get("kind")), str(e.get("channel", ""))
        if kind == "bias" and channel and channel != drive_channel:
            continue   # an offset of the measured channel: not part of the FE model
        raise UnsupportedFeature(f"instrument[{i}] (kind {kind!r} on {channel or 'the drive'!r})",
                                 "an instrument transform of the drive has no FEBio counterpart")


def _check_model(model: Any) -> None:
    if model.bc.springs:
        raise UnsupportedFeature("boundary.compliance", "a distributed elastic support "
                                 "(compliance above 0) has no export")
    rig = model.bc.rigid
    if rig is not None and rig.mode == "force" and tuple(rig.components) != (0, 1, 2):
        raise UnsupportedFeature(f"indenter.components = {list(rig.components)} under force control",
                                 "a rigid body in FEBio ties all three directions")


def febio_model(model_file: str | os.PathLike, *, session: str | os.PathLike | None = None,
                protocol: str | None = None, strict: bool = False) -> tuple[ET.ElementTree, dict[str, Any]]:
    """The FEBio model of ``model_file`` (an FE model file) and a summary of what it holds.

    ``session``: drive the indenter by that experiment file's (or CSV record's) recorded tip
    position or force (``[indenter] mode``) of ``protocol`` (needed when it has several).
    Raises :class:`SkinkitError` (one line) for a lumped model, a bad file, and
    :class:`UnsupportedFeature` for a feature without an FEBio counterpart. A feature whose
    nearest FEBio counterpart differs in a stated way (the GOH fibres' Macaulay switch) is
    exported and listed in ``summary["approximations"]``; ``strict``: refused instead.
    """
    from skinkit.forward import model_kind, read_description

    spec = read_description(model_file)
    if model_kind(spec) == "lumped":
        raise SkinkitError(f"{model_file}: is a lumped model; FEBio export needs a finite-element "
                           "model ([geometry] and [[layers]])")
    mode = str(dict(spec.get("indenter", {}) or {}).get("mode", "displacement"))
    check_supported(spec, "tip_force" if mode == "force" else "tip_position")
    model, drive = _build(dict(spec), session, protocol)
    _check_model(model)
    root = ET.Element("febio_spec", version=FEBIO_SPEC_VERSION)
    root.append(ET.Comment(f" written by skinkit from {Path(model_file).name} (model "
                           f"{model.name!r}); units: {UNITS}; FEBio spec {FEBIO_SPEC_VERSION} "))
    ET.SubElement(root, "Module", type="solid")
    _control(root, drive)
    notes: list[str] | None = None if strict else []
    mats = _materials(root, model, notes)
    probe = _probe_box(model)
    _mesh(root, model, probe)
    _domains(root, model, mats, probe is not None)
    lcs = _load_data_ids(drive)
    _boundary(root, model, drive, lcs)
    if probe is not None:
        _rigid(root, model, drive, lcs)
    _load_data(root, drive, lcs)
    _output(root)
    ET.indent(root, space="  ")
    conn = hex27_connectivity(model.mesh.nodes, model.mesh.elements)
    bad = int(np.sum(gauss_jacobians(model.mesh.nodes[conn]).min(axis=1) <= 0))
    summary = {"model": model.name, "nodes": model.mesh.n_nodes, "elements": model.mesh.n_elements,
               "inverted_at_gauss_points": bad, "approximations": list(notes or []),
               "materials": [m.region for m in model.problem.materials],
               "drive": None if drive is None else {"mode": drive.mode, "source": drive.source,
                                                    "steps": drive.n_steps, "duration": drive.duration},
               "spec": FEBIO_SPEC_VERSION, "units": UNITS}
    return ET.ElementTree(root), summary


def write_feb(tree: ET.ElementTree, path: str | os.PathLike) -> None:
    """Write ``tree`` to ``path`` (UTF-8, with the XML declaration)."""
    # the declaration written by hand: ElementTree's uses single quotes, which not every
    # hand-written XML reader accepts
    body = ET.tostring(tree.getroot(), encoding="unicode")
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write('<?xml version="1.0" encoding="UTF-8"?>\n')
        f.write(body)
        f.write("\n")


def _control(root: ET.Element, drive: Drive | None) -> None:
    n, T = (drive.n_steps, drive.duration) if drive is not None else (1, 1.0)
    dt = T / n
    c = ET.SubElement(root, "Control")
    ET.SubElement(c, "analysis").text = "STATIC"       # quasi-static in time, as skinkit solves
    ET.SubElement(c, "time_steps").text = str(n)
    add_param(c, "step_size", dt)
    ts = ET.SubElement(c, "time_stepper", type="default")
    ET.SubElement(ts, "max_retries").text = "10"
    ET.SubElement(ts, "opt_iter").text = "10"
    add_param(ts, "dtmin", dt * 1e-3)
    add_param(ts, "dtmax", dt)                          # never coarser than skinkit's steps
    ET.SubElement(ts, "aggressiveness").text = "0"
    add_param(ts, "cutback", 0.5)
    s = ET.SubElement(c, "solver", type="solid")
    ET.SubElement(s, "symmetric_stiffness").text = "symmetric"


def _materials(root: ET.Element, model: Any, notes: list[str] | None) -> dict[str, str]:
    """``<Material>``: one per layer, then the rigid body; region -> material name."""
    sec = ET.SubElement(root, "Material")
    names: dict[str, str] = {}
    for i, m in enumerate(model.problem.materials):
        names[m.region] = m.region
        sec.append(material_element(m, i + 1, m.region, f"layers[{i}] ({m.region})", notes))
    if model.bc.rigid is not None and tuple(model.bc.rigid.components) == (0, 1, 2):
        rb = _rigid_name(model)
        el = ET.SubElement(sec, "material", id=str(len(names) + 1), name=rb, type="rigid body")
        add_param(el, "density", 1.0)
        ET.SubElement(el, "center_of_mass").text = ",".join(
            fmt(v) for v in model.mesh.nodes[model.bc.rigid.nodes].mean(axis=0) * M_TO_MM)
    return names


def _rigid_name(model: Any) -> str:
    regions = set(model.mesh.regions)
    name = "indenter"
    while name in regions:
        name = "rigid_" + name
    return name


def _probe_box(model: Any) -> np.ndarray | None:
    """``(8, 3)`` [m] corners (hex8 order) of the rigid body's own element: a box above the tied
    nodes, sharing none of them (a rigid body in FEBio is made of its elements)."""
    rig = model.bc.rigid
    if rig is None or tuple(rig.components) != (0, 1, 2):
        return None
    X = model.mesh.nodes[rig.nodes]
    lo, hi = X.min(axis=0), X.max(axis=0)
    h = _PROBE_HEIGHT * float(max(hi[0] - lo[0], hi[1] - lo[1], 1e-6))
    z0 = float(model.mesh.nodes[:, 2].max())
    return np.array([[lo[0], lo[1], z0 + h], [hi[0], lo[1], z0 + h], [hi[0], hi[1], z0 + h],
                     [lo[0], hi[1], z0 + h], [lo[0], lo[1], z0 + 2 * h], [hi[0], lo[1], z0 + 2 * h],
                     [hi[0], hi[1], z0 + 2 * h], [lo[0], hi[1], z0 + 2 * h]])


def _csv(ids: Any) -> str:
    return ",".join(str(int(i)) for i in ids)


def _mesh(root: ET.Element, model: Any, probe: np.ndarray | None) -> None:
    mesh = model.mesh
    sec = ET.SubElement(root, "Mesh")
    nodes = ET.SubElement(sec, "Nodes", name="tissue")
    for i, x in enumerate(mesh.nodes * M_TO_MM):
        ET.SubElement(nodes, "node", id=str(i + 1)).text = ",".join(fmt(v) for v in x)
    conn = hex27_connectivity(mesh.nodes, mesh.elements) + 1
    eid = 1
    for region in mesh.regions:
        els = ET.SubElement(sec, "Elements", type="hex27", name=region)
        for e in mesh.region_elements(region):
            ET.SubElement(els, "elem", id=str(eid)).text = _csv(conn[e])
            eid += 1
    if probe is not None:
        pn = ET.SubElement(sec, "Nodes", name="probe")
        for k, x in enumerate(probe * M_TO_MM):
            ET.SubElement(pn, "node", id=str(mesh.n_nodes + k + 1)).text = ",".join(fmt(v) for v in x)
        pe = ET.SubElement(sec, "Elements", type="hex8", name="probe")
        ET.SubElement(pe, "elem", id=str(eid)).text = _csv(mesh.n_nodes + 1 + np.arange(8))
    for name, ids in mesh.node_sets.items():
        ET.SubElement(sec, "NodeSet", name=name).text = _csv(np.asarray(ids) + 1)
    if model.bc.rigid is not None:
        ET.SubElement(sec, "NodeSet", name="indenter_tied").text = _csv(model.bc.rigid.nodes + 1)


def _domains(root: ET.Element, model: Any, names: dict[str, str], probe: bool) -> None:
    sec = ET.SubElement(root, "MeshDomains")
    for region in model.mesh.regions:
        ET.SubElement(sec, "SolidDomain", name=region, mat=names[region])
    if probe:
        ET.SubElement(sec, "SolidDomain", name="probe", mat=_rigid_name(model))


def _load_data_ids(drive: Drive | None) -> dict[str, int]:
    if drive is None:
        return {}
    curves = list(drive.curves.values()) + drive.measured
    return {c.name: i + 1 for i, c in enumerate(curves)}


def _boundary(root: ET.Element, model: Any, drive: Drive | None, lcs: dict[str, int]) -> None:
    sec = ET.SubElement(root, "Boundary")
    for s in model.fixed_sets:
        bc = ET.SubElement(sec, "bc", name=f"fixed_{s}", node_set=s, type="zero displacement")
        for d in ("x_dof", "y_dof", "z_dof"):
            ET.SubElement(bc, d).text = "1"
    rig = model.bc.rigid
    if rig is None:
        return
    if tuple(rig.components) == (0, 1, 2):
        bc = ET.SubElement(sec, "bc", name="indenter_rigid", node_set="indenter_tied", type="rigid")
        ET.SubElement(bc, "rb").text = _rigid_name(model)
        return
    # a frictionless (partly tied) indenter under displacement control: each tied component of
    # every node follows the programme, the others are free -- skinkit's constraint exactly
    for c, curve in (drive.curves.items() if drive is not None else []):
        bc = ET.SubElement(sec, "bc", name=f"indenter_{'xyz'[c]}", node_set="indenter_tied",
                           type="prescribed displacement")
        ET.SubElement(bc, "dof").text = "xyz"[c]
        ET.SubElement(bc, "value", lc=str(lcs[curve.name])).text = "1"
        ET.SubElement(bc, "relative").text = "0"


def _rigid(root: ET.Element, model: Any, drive: Drive | None, lcs: dict[str, int]) -> None:
    sec = ET.SubElement(root, "Rigid")
    rb = _rigid_name(model)
    fixed = ET.SubElement(sec, "rigid_bc", name="indenter_no_rotation", type="rigid_fixed")
    ET.SubElement(fixed, "rb").text = rb
    for d in ("Ru_dof", "Rv_dof", "Rw_dof"):
        ET.SubElement(fixed, d).text = "1"           # skinkit's rigid region only translates
    if drive is None:
        return
    for c, curve in drive.curves.items():
        if drive.mode == "displacement":
            el = ET.SubElement(sec, "rigid_bc", name=f"indenter_{'xyz'[c]}", type="rigid_displacement")
            ET.SubElement(el, "rb").text = rb
            ET.SubElement(el, "dof").text = "xyz"[c]
        else:
            el = ET.SubElement(sec, "rigid_load", name=f"indenter_F{'xyz'[c]}", type="rigid_force")
            ET.SubElement(el, "rb").text = rb
            ET.SubElement(el, "dof").text = "R" + "xyz"[c]
            ET.SubElement(el, "load_type").text = "0"
        ET.SubElement(el, "value", lc=str(lcs[curve.name])).text = "1"
        ET.SubElement(el, "relative").text = "0"


def _load_data(root: ET.Element, drive: Drive | None, lcs: dict[str, int]) -> None:
    if drive is None:
        return
    sec = ET.SubElement(root, "LoadData")
    for curve in list(drive.curves.values()) + drive.measured:
        lc = ET.SubElement(sec, "load_controller", id=str(lcs[curve.name]), name=curve.name,
                           type="loadcurve")
        ET.SubElement(lc, "interpolate").text = "LINEAR"
        ET.SubElement(lc, "extend").text = "CONSTANT"
        pts = ET.SubElement(lc, "points")
        for t, v in zip(curve.times, curve.values, strict=True):
            ET.SubElement(pts, "pt").text = f"{fmt(t)},{fmt(v)}"


def _output(root: ET.Element) -> None:
    out = ET.SubElement(root, "Output")
    plot = ET.SubElement(out, "plotfile", type="febio")
    for var in ("displacement", "stress", "reaction forces"):
        ET.SubElement(plot, "var", type=var)
