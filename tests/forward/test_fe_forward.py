"""The finite-element forward model driven by a session: sensitivities, workers, surfaces, errors."""

from __future__ import annotations

import copy

import _directional
import numpy as np
import pytest

from skinkit.errors import ForwardError, SchemaError
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations, SurfaceProfile

pytestmark = pytest.mark.needs_plugins

#: a small layered disc: QLV skin with pre-stretch, an inclusion, a softening history
SPEC = {
    "model": {"name": "small"},
    "geometry": {"kind": "disc", "diameter": "20 mm", "indenter_diameter": "4 mm", "n_inner": 2, "n_ring": 2},
    "layers": [
        {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "qlv",
         "options": {"elastic": "neo-hookean-ni", "terms": 1},
         "parameters": {"mu": "15 kPa", "K": "500 kPa", "g1": 0.3, "tau1": "2 s"},
         "prestress": {"stretch": [1.05, 1.02], "angle": "20 deg"}},
        {"name": "subdermal", "thickness": "3.5 mm", "elements": 1, "law": "neo-hookean-enu",
         "parameters": {"E": "10 kPa", "nu": 0.45}},
    ],
    "fields": [
        {"name": "inc", "kind": "inclusion", "layers": ["skin"], "x": "2 mm", "y": "1 mm", "radius": "2 mm",
         "ratio": 2.0},
        {"name": "band", "kind": "band", "layers": ["subdermal"], "depth": "2 mm", "half_width": "0.5 mm",
         "ratio": 0.5},
        {"name": "soft", "kind": "softening", "layers": ["skin"], "softening": 0.2},
    ],
    "indenter": {"mode": "force"},
    "drive": {"max_step": "1 s"},
    "solver": {"rtol": 1e-12},
}
REF = np.array([[3e-3, 0, 0], [0, 4e-3, 0], [-5e-3, -2e-3, 0], [1e-3, 1e-3, 0]])


def session(mode: str = "force", two: bool = False) -> Observations:
    """Two protocols of a 0.1 Hz sinusoid (normal and oblique) at 100 Hz, points at 1 Hz: its
    first 7 s (to the peak and a third of the way back: loading, then unloading through the
    viscous history; 7 steps, not 10, so the tests of every parameter stay short)."""
    T = np.arange(0, 7.0001, 0.01)
    s = 0.5 * (1 - np.cos(2 * np.pi * 0.1 * T))
    out = {}
    for name, direc in (("normal", (0, 0, -1)), ("oblique", (0.3, 0.2, -1)))[: 2 if two else 1]:
        d = np.asarray(direc, float)
        F = 0.01 * s[:, None] * d
        X = 0.5e-3 * s[:, None] * d
        tf = np.arange(0, 7.0001, 1.0)
        pos = X if mode == "displacement" else 0 * X
        chans = {"tip_force": Channel("tip_force", T, F, noise=1e-4),
                 "tip_position": Channel("tip_position", T, pos, noise=1e-6),
                 "points": Channel("points", tf, np.repeat(REF[:, None], tf.size, 1), noise=5e-6,
                                   reference=REF)}
        out[name] = ProtocolObservations(Protocol(name), chans)
    return Observations(out, None, "test")


@pytest.fixture(scope="module")
def forward():
    from skinkit.forward import load
    return lambda spec, **kw: load(spec, **{"workers": 1, **kw})


def _scale(pset, names) -> dict[str, float]:
    """Each parameter's size for its difference step (1e-3 where it is near 0: fractions, angles)."""
    return {nm: max(abs(pset.param(nm).value), 1e-3) for nm in names}


@pytest.mark.parametrize("mode", ["force", "displacement"])
def test_sensitivities_match_central_differences(forward, mode):
    """Every law, Prony, pre-stretch and field parameter, through the viscous history: the
    analytic derivative along a random direction of all of them (:mod:`_directional`: each
    parameter weighted to move its most sensitive channel as much as any other parameter does)
    against central differences of whole solves along it.

    Tolerance: the central difference with h = 1e-6 of each parameter's size (times its
    component, at most 150) has a truncation error ~(step)² |f'''| (below 1e-7 relative) and a
    solver error ~rtol |f| / h = 1e-6 relative; 2e-5 of the channel's largest derivative leaves
    a margin of 20."""
    spec = copy.deepcopy(SPEC)
    spec["indenter"]["mode"] = mode
    m = forward(spec)
    obs = session(mode)
    pset = m.parameters()
    pred = m.predict(pset, obs, sensitivities=True)
    assert set(pred.methods) == set(pset.names)
    assert set(pred.methods.values()) == {"analytic"}
    _, worst = _directional.check(m, obs, pset.names, _scale(pset, pset.names), seed=11, tol=2e-5,
                                  pred=pred)
    assert worst > 0


def test_workers_give_identical_numbers(forward):
    """Two protocols in this process and on two worker processes: the same bits."""
    obs = session(two=True)
    a = forward(SPEC, workers=1)
    b = forward(SPEC, workers=2)
    pa = a.predict(a.parameters(), obs, sensitivities=["skin.mu", "skin.prestretch.l1"])
    pb = b.predict(b.parameters(), obs, sensitivities=["skin.mu", "skin.prestretch.l1"])
    b.close()
    for (_, _, x), (_, _, y) in zip(pa.items(), pb.items(), strict=True):
        assert np.array_equal(x.values, y.values)
        for k in x.d:
            assert np.array_equal(x.d[k], y.d[k])


def test_one_protocol_on_two_workers_gives_its_solver_both(forward, monkeypatch):
    """One protocol and two workers: the protocol is solved with its sparse solver on two
    threads (recorded in the solve's info), to the same numbers as on one worker up to the
    rounding of the factorisation's sums (the Newton tolerance is far coarser)."""
    monkeypatch.delenv("SKINKIT_SOLVE_CACHE", raising=False)    # both solved, neither read back
    obs = session()
    a = forward(SPEC, workers=1)
    b = forward(SPEC, workers=2)
    names = ["skin.mu", "skin.prestretch.l1"]
    pa = a.predict(a.parameters(), obs, sensitivities=names)
    pb = b.predict(b.parameters(), obs, sensitivities=names)
    assert b.predict_many([]) == []      # no protocol at all: nothing solved, no pool
    b.close()
    assert pa.info["protocols"]["normal"]["threads"] == 1 and pb.info["protocols"]["normal"]["threads"] == 2
    for (_, _, x), (_, _, y) in zip(pa.items(), pb.items(), strict=True):
        scale = float(np.nanmax(np.abs(x.values))) or 1.0
        np.testing.assert_allclose(y.values, x.values, rtol=1e-7, atol=1e-9 * scale)
        for k in x.d:
            dscale = float(np.nanmax(np.abs(x.d[k]))) or 1.0
            np.testing.assert_allclose(y.d[k], x.d[k], rtol=1e-6, atol=1e-8 * dscale)


def test_predictions_on_exactly_the_observed_times_and_points(forward):
    m = forward(SPEC)
    obs = session()
    pred = m.predict(m.parameters(), obs)
    assert pred.inputs == {"normal": "tip_force"}
    assert set(pred.protocols["normal"]) == {"tip_position", "points"}
    for c in ("tip_position", "points"):
        assert pred.protocols["normal"][c].values.shape == obs["normal"].channels[c].values.shape
    # the unloaded first frame: points where they were measured
    assert np.allclose(pred.protocols["normal"]["points"].values[:, 0], REF, atol=1e-12)
    # pushing into the skin moves the tip down, by less than the skin's thickness
    z = pred.protocols["normal"]["tip_position"].values[:, 2]
    assert z.min() < 0 and z.min() > -5e-3


def test_fields_at_unit_factor_are_the_model_without_them(forward):
    """φ = 1 exactly: ratio 1 and softening 0 give the bits of the model without fields."""
    spec = copy.deepcopy(SPEC)
    bare = copy.deepcopy(SPEC)
    bare.pop("fields")
    spec["fields"][0]["ratio"] = 1.0
    spec["fields"][1]["ratio"] = 1.0
    spec["fields"][2]["softening"] = 0.0
    obs = session()
    a, b = forward(spec), forward(bare)
    pa = a.predict(a.parameters(), obs)
    pb = b.predict(b.parameters(), obs)
    for (_, _, x), (_, _, y) in zip(pa.items(), pb.items(), strict=True):
        assert np.max(np.abs(x.values - y.values)) <= 1e-12 * np.max(np.abs(y.values))


def _cap(R: float = 0.05, n: int = 41, half: float = 0.012) -> SurfaceProfile:
    """A spherical cap z = sqrt(R² - r²) - R (top at 0) sampled on a grid [m]."""
    g = np.linspace(-half, half, n)
    X, Y = np.meshgrid(g, g)
    Z = np.sqrt(R ** 2 - X ** 2 - Y ** 2) - R
    pts = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    return SurfaceProfile(pts, np.ones(len(pts)))


def test_points_embedded_along_the_true_normal():
    """On a sphere of radius R the normal points to the centre. A measured surface point is
    moved onto the fitted surface and then d along its normal: exactly d along the returned
    normal, which is the sphere's to the slope error of the fitted surface, and on the sphere
    of radius R - d to the height error of the fit (bounded by twice the fit's own largest
    misfit at the profile points, plus the µm of interpolating between them)."""
    from skinkit.fem.embed import fit_surface, surface_points
    from skinkit.fem.model import build_mesh
    mesh = build_mesh(SPEC)
    R = 0.05
    fit = fit_surface(mesh, _cap(R).points, 1.5e-3, keep=())
    th = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    xy = np.column_stack([5e-3 * np.cos(th), 5e-3 * np.sin(th)])
    top = np.column_stack([xy, np.sqrt(R ** 2 - (xy ** 2).sum(1)) - R])
    d = 0.5e-3
    on, n0 = surface_points(fit.mesh, top, 0.0)
    emb, n = surface_points(fit.mesh, top, d)
    assert np.allclose(on - emb, d * n, atol=1e-15)
    centre = np.array([0, 0, -R])
    tol = 2 * fit.max_abs + 1e-6
    assert np.allclose(np.linalg.norm(on - centre, axis=1), R, atol=tol)
    assert np.allclose(np.linalg.norm(emb - centre, axis=1), R - d, atol=tol)
    # the normal: the sphere's, within the slope error (height error over the element size)
    assert np.allclose(n, (on - centre) / np.linalg.norm(on - centre, axis=1)[:, None], atol=tol / 1e-3)
    # the measured point lies on the normal through its surface point (projection along it)
    off = top - on
    assert np.allclose(off - np.einsum("mi,mi->m", off, n)[:, None] * n, 0, atol=1e-9)


def test_profile_that_does_not_cover_the_mesh_is_refused(forward):
    spec = copy.deepcopy(SPEC)
    spec["surface"] = {"fit": True}
    obs = session()
    small = _cap(half=0.004)
    obs = Observations(obs.protocols, small, "test")
    m = forward(spec)
    with pytest.raises(ForwardError, match="does not cover the mesh"):
        m.predict(m.parameters(), obs)
    spec["surface"]["outside"] = "nearest"
    pred = forward(spec).predict(m.parameters(), obs)
    assert np.isfinite(pred.protocols["normal"]["tip_position"].values).all()


def test_session_lacking_the_drive_channel_is_named(forward):
    obs = session()
    po = obs["normal"]
    chans = {k: v for k, v in po.channels.items() if k != "tip_force"}
    bad = Observations({"normal": ProtocolObservations(po.protocol, chans)}, None, "x")
    m = forward(SPEC)
    with pytest.raises(ForwardError, match="'normal'.*tip_force"):
        m.predict(m.parameters(), bad)


def test_point_outside_the_model_is_named(forward):
    obs = session()
    po = obs["normal"]
    far = np.array([[0.05, 0, 0]])
    tf = po.channels["points"].time_s
    ch = Channel("points", tf, np.repeat(far[:, None], tf.size, 1), noise=5e-6, reference=far)
    bad = Observations({"normal": ProtocolObservations(po.protocol, {**po.channels, "points": ch})},
                       None, "x")
    m = forward(SPEC)
    with pytest.raises(ForwardError, match="outside"):
        m.predict(m.parameters(), bad)


def test_unknown_parameter_is_named(forward):
    m = forward(SPEC)
    with pytest.raises(SchemaError, match="nope"):
        m.predict(m.parameters(), session(), sensitivities=["nope"])


def test_instrument_parameters_match_central_differences(forward):
    """Biases on the driving force (load derivatives), a tilt of the probe axis (drive and
    measured tip channels turned), a series compliance and a similarity of the points, along a
    random direction of them all: the same tolerance as for the material parameters."""
    spec = copy.deepcopy(SPEC)
    spec.pop("fields")
    spec["instrument"] = [
        {"kind": "bias", "channel": "tip_force", "component": 2, "basis": "constant", "parameter": "off.z",
         "value": 1e-3},
        {"kind": "bias", "channel": "tip_force", "component": 0, "basis": "time", "parameter": "drift.x",
         "value": 1e-5},
        {"kind": "tilt", "parameter": "tilt.angle", "value": 0.05, "azimuth": 0.3,
         "azimuth_parameter": "tilt.azimuth"},
        {"kind": "series", "channel": "tip_position", "source": "tip_force", "parameter": "comp.c",
         "value": 1e-3},
        {"kind": "similarity", "channel": "points", "mode": "scale", "parameter": "trk.scale",
         "value": 0.01},
        {"kind": "similarity", "channel": "points", "mode": "rotation", "parameter": "trk.rot",
         "value": 0.01},
    ]
    m = forward(spec)
    obs = session()
    names = ["off.z", "drift.x", "tilt.angle", "comp.c", "trk.scale", "trk.rot"]
    pset = m.parameters()
    assert set(names) <= set(pset.names)
    _directional.check(m, obs, names, _scale(pset, names), seed=12, tol=2e-5)


def test_a_measured_reference_is_distorted_like_every_frame(forward):
    """A tracker's scale and rotation error distorts the reference frame it measures as much as
    any other frame: with the reference taken from frame 0, the points are embedded where the
    undistorted reference puts them, so frame 0 is predicted exactly as recorded (the error
    leaves only its share of the displacements), and the derivatives — the embedding's share
    by differences of the interpolated field, step 1e-4 — match whole-prediction central
    differences. Tolerance 1e-4 of the largest derivative: the embedding's difference step
    moves a point 0.5 µm, across an element face at worst, where the field's gradient jumps
    (quadratic elements: C0 only) — a relative error of the step's order."""
    spec = copy.deepcopy(SPEC)
    spec.pop("fields")
    spec["instrument"] = [
        {"kind": "similarity", "channel": "points", "mode": "scale", "parameter": "trk.scale", "value": 0.02},
        {"kind": "similarity", "channel": "points", "mode": "rotation", "parameter": "trk.rot",
         "value": 0.03},
    ]
    obs = session("force")
    po = obs["normal"]
    ch = po.channels["points"]
    measured = Channel("points", ch.time_s, ch.values, noise=ch.noise, reference=REF, reference_frame=0)
    obs = Observations({"normal": ProtocolObservations(po.protocol, {**po.channels, "points": measured})},
                       None, "measured reference")
    m = forward(spec)
    pset = m.parameters()
    names = ["trk.scale", "trk.rot"]
    pred = m.predict(pset, obs, sensitivities=names)
    pts = pred.protocols["normal"]["points"]
    np.testing.assert_allclose(pts.values[:, 0], REF, atol=1e-12)
    moved = np.abs(pts.values[:, -1] - REF).max()
    assert moved > 1e-5                    # the skin did move: frame 0 is not trivially the reference
    # the error is proportional to the displacement: 2 % of it, turned by 0.03 rad, not 2 % of |X|
    exact = copy.deepcopy(obs)
    exact["normal"].channels["points"] = Channel("points", ch.time_s, ch.values, noise=ch.noise,
                                                 reference=REF)
    off = m.predict(pset, exact).protocols["normal"]["points"].values
    assert np.abs(off[:, 0] - REF).max() > 0.01 * np.linalg.norm(REF, axis=1).min()
    for nm in names:
        p = pset.param(nm)
        h = 1e-6
        up = m.predict(pset.with_values({nm: p.value + h}), obs).protocols["normal"]["points"].values
        dn = m.predict(pset.with_values({nm: p.value - h}), obs).protocols["normal"]["points"].values
        fd = (up - dn) / (2 * h)
        scale = max(np.abs(fd).max(), np.abs(pts.d[nm]).max())
        assert scale > 0
        assert np.abs(pts.d[nm] - fd).max() / scale < 1e-4, nm


def test_a_measured_reference_is_the_origin_of_every_predicted_frame(forward):
    """With a measured reference a track knows positions only relative to it: the prediction
    is the reference plus the model's displacement since that frame, in every component —
    the points are embedded on the model's surface, so its reference noise normal to the surface
    was lost before (χ²/N of the points 0.97 on exact-model sessions). Exact part: noise in z
    only leaves the embedding as it was, so the displacements equal the exact reference's to
    solver precision. Statistical part: 300 points, 7 frames after the reference, σ = 5 µm; the
    frame-mean of each point's normalised residual has variance 1 + 1/m (the reference's noise is
    in every frame); 0.7–1.3 is ±3.7 standard errors of a variance from 300 samples (the lost
    reference noise made it 1/m: 0.14)."""
    m = forward(SPEC)
    obs = session()
    po = obs["normal"]
    ch = po.channels["points"]
    rng = np.random.default_rng(5)
    r = 8e-3 * np.sqrt(rng.uniform(size=300))
    a = rng.uniform(0, 2 * np.pi, 300)
    grid = np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros(300)])

    def observe(values, reference, frame):
        c = Channel("points", ch.time_s, values, noise=5e-6, reference=reference, reference_frame=frame)
        protocol = ProtocolObservations(po.protocol, {**po.channels, "points": c})
        o = Observations({"normal": protocol}, None, "t")
        return o, m.predict(m.parameters(), o).protocols["normal"]["points"].values

    _, exact = observe(np.repeat(grid[:, None], ch.time_s.size, 1), grid, None)
    assert np.abs(exact[:, -1] - exact[:, 0]).max() > 1e-5          # the skin moved
    ref = grid + np.array([0, 0, 5e-6]) * rng.standard_normal(grid.shape)
    _, pred = observe(exact, ref, 0)
    np.testing.assert_allclose(pred[:, 0], ref, rtol=0, atol=1e-15)
    np.testing.assert_allclose(pred - pred[:, :1], exact - exact[:, :1], rtol=0, atol=1e-12)
    noisy = exact + 5e-6 * rng.standard_normal(exact.shape)
    o, pred = observe(noisy, noisy[:, 0].copy(), 0)
    resid = (pred - noisy)[:, 1:] / 5e-6
    nm = resid.shape[1]
    ratio = resid.mean(axis=1).var(axis=0) / (1 + 1 / nm)
    assert np.all((ratio > 0.7) & (ratio < 1.3)), ratio
    z = o["normal"].channels["points"].normalised(pred)
    assert abs(float((z**2).sum()) / z[:, 1:].size - 1) < 4 * np.sqrt(2 / z[:, 1:].size)
