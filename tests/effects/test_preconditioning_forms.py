"""The ``preconditioning`` effect's two forms: softening that develops over the loading strokes
(``cycles``, the default) and softening with the largest load so far (``largest-load``).

Closed forms on a lumped linear element, complex-step sensitivities against central
differences, the finite-element ``softening`` field with ``cycles`` on a small disc, and the
errors of bad input.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

from skinkit.errors import EffectError, ForwardError
from skinkit.fem.errors import ModelError
from skinkit.fem.fields import Field
from skinkit.forward.effects import resolve
from skinkit.forward.lumped import build_lumped
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

pytestmark = pytest.mark.needs_plugins

K_EL, AMP = 50.0, 6e-3          # [N/m], [m]
N_CYCLES = 5
DT = 0.05                       # [s]; the ramps last 2 s: 40 samples, peaks sampled exactly


def triangles(n: int = N_CYCLES, amp: float = AMP, ramp: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """``(t (T,) [s], u (T,) [m])``: ``n`` identical triangle cycles 0 -> amp -> 0."""
    t = np.arange(0.0, 2 * ramp * n + DT / 2, DT)
    phase = np.mod(t, 2 * ramp) / ramp
    return t, amp * np.minimum(phase, 2 - phase)


def session(parts: list[tuple[np.ndarray, np.ndarray]]) -> Observations:
    """Protocols ``p0, p1, ...`` driven along x by ``tip_position`` ``u``, ``tip_force`` to predict."""
    out = {}
    for k, (t, u) in enumerate(parts):
        D = np.full((t.size, 3), np.nan)
        D[:, 0] = u
        F = np.full((t.size, 3), np.nan)
        F[:, 0] = 0.0
        chans = {"tip_position": Channel("tip_position", t, D, noise=1e-6),
                 "tip_force": Channel("tip_force", t, F, noise=1e-3)}
        out[f"p{k}"] = ProtocolObservations(Protocol(f"p{k}", kind="external"), chans)
    return Observations(out, None, "test")


def lumped(effect: dict[str, Any] | None = None, relaxation: bool = False) -> Any:
    """A linear lumped element (optionally with a Prony term) with a preconditioning table."""
    lt: dict[str, Any] = {"elastic": "linear", "parameters": {"k": K_EL}}
    if relaxation:
        lt["relaxation"] = [{"g": 0.3, "tau": "1.5 s"}]
    spec = {"model": {"kind": "lumped", "name": "pre"}, "lumped": lt}
    tables = [{"name": "preconditioning", **effect}] if effect is not None else []
    return build_lumped(spec, resolve(tables, "lumped"))


def force(model: Any, obs: Observations, values: dict[str, float] | None = None) -> list[np.ndarray]:
    ps = model.parameters().with_values(values or {})
    pred = model.predict(ps, obs)
    return [pred.protocols[p]["tip_force"].values[:, 0] for p in obs.names]


def peaks(t: np.ndarray, f: np.ndarray, n: int = N_CYCLES, ramp: float = 2.0) -> np.ndarray:
    """The force at the peak of each cycle (t = ramp, 3 ramp, ...)."""
    idx = [int(np.argmin(np.abs(t - (2 * k + 1) * ramp))) for k in range(n)]
    return f[idx]


# -- closed forms -------------------------------------------------------------------------------
@pytest.mark.parametrize(("s", "c"), [(0.2, 1.0), (0.35, 2.5), (0.6, 0.3)])
def test_cycle_peaks_fall_as_the_closed_form_and_level_off(s, c):
    """Peak k (k = 1..N) = k_el amp (1 − s (1 − e^(−k/cycles))): falling, each fall smaller."""
    t, u = triangles()
    f = force(lumped({"softening": s, "cycles": c}), session([(t, u)]))[0]
    k = np.arange(1, N_CYCLES + 1)
    exact = K_EL * AMP * (1 - s * (1 - np.exp(-k / c)))
    assert np.allclose(peaks(t, f), exact, rtol=1e-13, atol=0)
    falls = -np.diff(peaks(t, f))
    assert np.all(falls > 0) and np.all(np.diff(falls) < 0)
    # and it levels off at 1 − s of the unsoftened peak: above it by s e^(−N/cycles)/(1 − s) of it
    last = peaks(t, f)[-1] / (K_EL * AMP * (1 - s)) - 1
    assert last > 0 and last == pytest.approx(s * np.exp(-N_CYCLES / c) / (1 - s), rel=1e-9, abs=1e-13)


def test_strokes_accumulate_across_protocols_in_session_order():
    """Two protocols of 2 and 3 cycles are one session of 5: the same peaks as one protocol."""
    t, u = triangles()
    t2, u2 = triangles(2)
    t3, u3 = triangles(3)
    m = lumped({"softening": 0.3, "cycles": 1.5})
    one = peaks(t, force(m, session([(t, u)]))[0])
    a, b = force(m, session([(t2, u2), (t3, u3)]))
    assert np.allclose(np.concatenate([peaks(t2, a, 2), peaks(t3, b, 3)]), one, rtol=1e-13, atol=0)


def test_largest_load_form_gives_equal_peaks():
    t, u = triangles()
    m = lumped({"form": "largest-load", "softening": 0.3})
    assert "preconditioning.cycles" not in m.parameters().names
    assert np.allclose(peaks(t, force(m, session([(t, u)]))[0]), K_EL * AMP * 0.7, rtol=1e-13, atol=0)


@pytest.mark.parametrize("c", [0.1, 1.0, 50.0])
def test_softening_zero_is_the_model_without_the_effect(c):
    """φ = 1 exactly at softening = 0, whatever ``cycles``: the same bits as no effect."""
    t, u = triangles()
    obs = session([(t, u)])
    without = force(lumped(relaxation=True), obs)[0]
    with_null = force(lumped({"softening": 0.0, "cycles": c}, relaxation=True), obs)[0]
    assert np.array_equal(with_null, without)


def test_old_lumped_tables_keep_the_largest_load_meaning():
    """``[lumped.preconditioning]`` with ``softening`` only (older model files) is largest-load."""
    t, u = triangles()
    spec = {"model": {"kind": "lumped"}, "lumped": {"elastic": "linear", "parameters": {"k": K_EL},
                                                    "preconditioning": {"softening": 0.3}}}
    m = build_lumped(spec)
    assert m.spec.preconditioning_form == "largest-load"
    assert np.allclose(peaks(t, force(m, session([(t, u)]))[0]), K_EL * AMP * 0.7, rtol=1e-13, atol=0)


def test_the_effect_writes_and_binds_each_form():
    from skinkit.forward.effects import apply_all
    base = {"model": {"kind": "lumped"}, "lumped": {"elastic": "linear", "parameters": {"k": K_EL}}}
    cyc = apply_all(base, resolve([{"name": "preconditioning", "softening": 0.2, "cycles": 2.0}], "lumped"))
    assert cyc["lumped"]["preconditioning"] == {"form": "cycles", "softening": 0.2, "cycles": 2.0}
    assert cyc["bindings"] == {"preconditioning.softening": "lumped.softening",
                               "preconditioning.cycles": "lumped.cycles"}
    big = apply_all(base, resolve([{"name": "preconditioning", "form": "largest-load", "softening": 0.2}],
                                  "lumped"))
    assert big["lumped"]["preconditioning"] == {"form": "largest-load", "softening": 0.2}
    assert big["bindings"] == {"preconditioning.softening": "lumped.softening"}


# -- sensitivities ------------------------------------------------------------------------------
@pytest.mark.parametrize("relaxation", [False, True])
def test_complex_step_sensitivities_match_central_differences(relaxation):
    """∂f/∂softening and ∂f/∂cycles by the complex step against central differences.

    Tolerance: f is smooth in both (an exponential), so the central difference with
    h = 1e-5 of the value has truncation error ~h² |f'''|/6 ~ 1e-10 relative and rounding
    ~1e-16/h ~ 1e-11; 1e-7 of the largest derivative leaves a wide margin."""
    t, u = triangles(3)
    t2, u2 = triangles(2, amp=0.7 * AMP)
    obs = session([(t, u), (t2, u2)])
    m = lumped({"softening": 0.25, "cycles": 1.7}, relaxation=relaxation)
    ps = m.parameters()
    names = ["preconditioning.softening", "preconditioning.cycles"]
    pred = m.predict(ps, obs, sensitivities=names)
    assert all(pred.methods[n] == "complex-step" for n in names)
    for n in names:
        v = ps.param(n).value
        h = 1e-5 * v
        up = force(m, obs, {n: v + h})
        dn = force(m, obs, {n: v - h})
        for k, p in enumerate(obs.names):
            fd = (up[k] - dn[k]) / (2 * h)
            cs = pred.protocols[p]["tip_force"].d[n][:, 0]
            assert np.abs(fd).max() > 0
            assert np.abs(cs - fd).max() <= 1e-7 * np.abs(fd).max(), (n, p)


def test_cycles_has_no_signature_at_the_null():
    """At softening = 0 the prediction does not depend on ``cycles`` (the score test holds it)."""
    t, u = triangles(3)
    m = lumped({"softening": 0.0, "cycles": 1.0})
    pred = m.predict(m.parameters(), session([(t, u)]), sensitivities=True)
    d = pred.protocols["p0"]["tip_force"].d
    assert np.all(d["preconditioning.cycles"] == 0)
    assert np.abs(d["preconditioning.softening"]).max() > 0


# -- finite elements ------------------------------------------------------------------------------
def test_field_phi_and_cycles_derivative():
    """φ(t) = 1 − s (1 − e^(−A(t)/cycles)) of a ``softening`` field with ``cycles``; ∂φ/∂cycles and
    ∂φ/∂softening by its complex step against central differences (relative 1e-8: φ is an
    exponential, h = 1e-6 of the value)."""
    s, c = 0.3, 1.4
    X, depth = np.zeros((2, 3, 3)), np.full((2, 3), 1e-3)
    for a in (0.0, 0.5, 1.0, 3.7):
        f = Field("soft", "softening", ["skin"], {"softening": s, "cycles": c}, strokes=lambda t, a=a: a)
        assert np.allclose(f.value(X, depth, 1.0), 1 - s * (1 - np.exp(-a / c)), rtol=1e-15, atol=0)
        for key, v in (("cycles", c), ("softening", s)):
            h = 1e-6 * v
            fp = Field("soft", "softening", ["skin"], {"softening": s, "cycles": c, key: v + h},
                       strokes=lambda t, a=a: a)
            fm = Field("soft", "softening", ["skin"], {"softening": s, "cycles": c, key: v - h},
                       strokes=lambda t, a=a: a)
            fd = (fp.value(X, depth, 1.0) - fm.value(X, depth, 1.0)) / (2 * h)
            assert np.allclose(f.derivative(key, X, depth, 1.0), fd, rtol=1e-8, atol=1e-14)
    # without cycles the field is the largest-load softening, as before
    g = Field("soft", "softening", ["skin"], {"softening": s}, level=lambda t: 0.5, strokes=lambda t: 9.0)
    assert np.all(g.value(X, depth, 1.0) == 1 - s * 0.5)


def test_running_strokes_of_a_drive():
    from skinkit.forward.drive import running_strokes
    d = np.array([[0, 0, -1.0], [0, 0, -2.0], [0, 0, -1.0], [0, 0, -2.0], [0, 0, 0.0]])
    assert np.allclose(running_strokes(d, 0.5, 2.0), [1.0, 1.5, 1.5, 2.0, 2.0])
    assert np.all(running_strokes(d, 0.5, 0.0) == 0.5)


#: a small two-layer disc, purely elastic, so with φ on both layers and the tip position imposed the
#: tip force is φ(t) times that of the model without the field
FE_SPEC: dict[str, Any] = {
    "model": {"name": "pre-fe"},
    "geometry": {"kind": "disc", "diameter": "20 mm", "indenter_diameter": "4 mm", "n_inner": 2, "n_ring": 2},
    "layers": [
        {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "neo-hookean-enu",
         "parameters": {"E": "60 kPa", "nu": 0.45}},
        {"name": "subdermal", "thickness": "3.5 mm", "elements": 1, "law": "neo-hookean-enu",
         "parameters": {"E": "10 kPa", "nu": 0.45}},
    ],
    "indenter": {"mode": "displacement"},
    "drive": {"max_step": "0.5 s"},
    "solver": {"rtol": 1e-12},
}


def _fe_session(cycles: int = 3) -> tuple[Observations, np.ndarray, np.ndarray]:
    """Trapezoid indentations (ramp 1 s to 0.3 mm, hold 0.5 s, back 1 s, rest 0.5 s) sampled at
    4 Hz: every solver step (0.5 s) is a sample and the drive at the steps is exact (the
    smoothing window holds 3 samples: interpolation). Returns the session, the step times and
    the strokes A at them."""
    t = np.arange(0.0, 3.0 * cycles + 1e-9, 0.25)
    ph = np.mod(t, 3.0)
    depth = 0.3e-3 * np.clip(np.minimum(ph, 2.5 - ph), 0.0, 1.0)
    X = np.zeros((t.size, 3))
    X[:, 2] = -depth
    chans = {"tip_position": Channel("tip_position", t, X, noise=1e-6),
             "tip_force": Channel("tip_force", t, 0 * X, noise=1e-4)}
    obs = Observations({"p": ProtocolObservations(Protocol("p", kind="external"), chans)}, None, "test")
    a = np.concatenate([[0.0], np.cumsum(np.maximum(np.diff(depth), 0.0))]) / depth.max()
    steps = np.isclose(np.mod(t, 0.5), 0.0) | np.isclose(np.mod(t, 0.5), 0.5)
    return obs, steps, a


def test_fe_softening_field_follows_the_strokes_and_differentiates_cycles():
    """Ratio of tip forces (field / no field) = 1 − s (1 − e^(−A/cycles)) at the solver steps;
    ∂force/∂cycles and ∂force/∂softening match central differences (2e-5 relative: solver error
    ~rtol/h, as the FE forward tests)."""
    from skinkit.forward import load
    s, c = 0.3, 1.2
    obs, steps, a = _fe_session()
    spec = copy.deepcopy(FE_SPEC)
    spec["fields"] = [{"name": "soft", "kind": "softening", "layers": ["skin", "subdermal"],
                       "softening": s, "cycles": c}]
    with load(FE_SPEC, workers=1) as plain, load(spec, workers=1) as soft:
        f0 = plain.predict(plain.parameters(), obs).protocols["p"]["tip_force"].values[:, 2]
        ps = soft.parameters()
        names = ["soft.cycles", "soft.softening"]
        pred = soft.predict(ps, obs, sensitivities=names)
        f1 = pred.protocols["p"]["tip_force"].values[:, 2]
        loaded = steps & (np.abs(f0) > 1e-3 * np.abs(f0).max())
        assert loaded.sum() >= 6
        phi = 1 - s * (1 - np.exp(-a / c))
        assert np.allclose(f1[loaded] / f0[loaded], phi[loaded], rtol=1e-8, atol=0)
        for n in names:
            v = ps.param(n).value
            h = 1e-6 * v
            up = soft.predict(ps.with_values({n: v + h}), obs).protocols["p"]["tip_force"].values[:, 2]
            dn = soft.predict(ps.with_values({n: v - h}), obs).protocols["p"]["tip_force"].values[:, 2]
            fd = (up - dn) / (2 * h)
            d = pred.protocols["p"]["tip_force"].d[n][:, 2]
            assert np.abs(fd).max() > 0
            assert np.abs(d - fd).max() <= 2e-5 * np.abs(fd).max(), n


# -- bad input ------------------------------------------------------------------------------------
def test_unknown_form_is_refused_naming_the_entry_and_the_forms():
    with pytest.raises(EffectError, match=r"effects\[0\]\.form.*'cycles', 'largest-load'.*'mullins'"):
        resolve([{"name": "preconditioning", "form": "mullins"}], "lumped")
    with pytest.raises(EffectError, match=r"effects\[0\]\.form.*only one form"):
        resolve([{"name": "viscoelastic", "form": "cycles"}], "lumped")
    # the largest-load form has no cycles parameter
    with pytest.raises(EffectError, match=r"unknown parameter.*cycles"):
        resolve([{"name": "preconditioning", "form": "largest-load", "cycles": 2.0}], "lumped")


@pytest.mark.parametrize("c", [0.0, -1.0])
def test_non_positive_cycles_are_refused_naming_the_entry(c):
    with pytest.raises(EffectError, match=r"effects\[0\]\.cycles.*outside the admissible range"):
        resolve([{"name": "preconditioning", "softening": 0.2, "cycles": c}], "lumped")
    spec = {"model": {"kind": "lumped"}, "lumped": {
        "elastic": "linear", "parameters": {"k": K_EL}, "preconditioning": {"softening": 0.2, "cycles": c}}}
    with pytest.raises(ForwardError, match=r"lumped\.preconditioning\.cycles.*positive"):
        build_lumped(spec)
    with pytest.raises(ModelError, match=r"cycles"):
        Field("soft", "softening", ["skin"], {"softening": 0.2, "cycles": c})


def test_bad_lumped_preconditioning_tables_are_refused():
    base = {"model": {"kind": "lumped"}, "lumped": {"elastic": "linear", "parameters": {"k": K_EL}}}
    for table, match in (({"form": "mullins", "softening": 0.1}, r"preconditioning\.form.*'cycles'"),
                         ({"form": "cycles", "softening": 0.1}, r"cycles form takes exactly"),
                         ({"form": "largest-load", "softening": 0.1, "cycles": 1.0}, r"largest-load form")):
        spec = copy.deepcopy(base)
        spec["lumped"]["preconditioning"] = table
        with pytest.raises(ForwardError, match=match):
            build_lumped(spec)
