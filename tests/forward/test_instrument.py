"""``[[instrument]]`` transforms: parsing, exact nulls, closed forms and derivatives against
central differences."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from skinkit.errors import ForwardError
from skinkit.forward import instrument as inst

RNG = np.random.default_rng(7)
T = np.linspace(0.0, 3.0, 31)
FORCE = RNG.standard_normal((31, 3))
POS = 1e-3 * RNG.standard_normal((31, 3))
PTS = 1e-2 * RNG.standard_normal((4, 31, 3))
PTS2 = PTS[..., :2].copy()

ENTRIES: list[dict[str, Any]] = [
    {"kind": "bias", "parameter": "off", "value": 0.02, "channel": "tip_force", "component": 2},
    {"kind": "bias", "parameter": "drift", "value": 5e-4, "channel": "tip_force", "component": 0,
     "basis": "time"},
    {"kind": "bias", "parameter": "zero", "value": 1e-4, "channel": "tip_position", "component": 1},
    {"kind": "series", "parameter": "comp", "value": 1e-3, "channel": "tip_position", "source": "tip_force"},
    {"kind": "tilt", "parameter": "tilt", "value": 0.05, "azimuth": 0.7, "azimuth_parameter": "az"},
    {"kind": "similarity", "parameter": "scale", "value": 0.01, "channel": "points", "mode": "scale"},
    {"kind": "similarity", "parameter": "rot", "value": 0.008, "channel": "points", "mode": "rotation"},
]
NAMES = ["off", "drift", "zero", "comp", "tilt", "az", "scale", "rot"]
#: step scale per parameter (the azimuth is an angle of order 1)
SCALE = {"off": 0.02, "drift": 5e-4, "zero": 1e-4, "comp": 1e-3, "tilt": 0.05, "az": 1.0, "scale": 0.01,
         "rot": 0.008}


def _set(entries: list[dict[str, Any]], name: str, value: float) -> list[inst.Entry]:
    out = []
    for e in entries:
        e = dict(e)
        if e["parameter"] == name:
            e["value"] = value
        if e.get("azimuth_parameter") == name:
            e["azimuth"] = value
        out.append(e)
    return inst.parse(out)


def _forward(entries: list[inst.Entry]) -> dict[str, np.ndarray]:
    """Force-driven chain: the recorded force -> skin force; predicted position, points -> recorded.
    The 'model' is a fixed linear map of the skin force (so its own derivatives are known)."""
    f, df = inst.drive(entries, "tip_force", T, FORCE, NAMES)
    M = np.array([[1e-3, 2e-4, 0], [0, 2e-3, 0], [1e-4, 0, 5e-3]])
    x, dx = f @ M.T, {n: a @ M.T for n, a in df.items()}
    pos, dpos = inst.measure(entries, "tip_position", T, x, dx, {"tip_force": (f, df)}, NAMES)
    pts, dpts = inst.measure(entries, "points", T, PTS, {}, {}, NAMES)
    p2, dp2 = inst.measure(entries, "points_2d", T, PTS2, {}, {}, NAMES)
    return {"f": f, "pos": pos, "pts": pts, "p2": p2,
            **{f"d{k}:{n}": a for k, d in (("f", df), ("pos", dpos), ("pts", dpts), ("p2", dp2))
               for n, a in d.items()}}


def test_parse_names_the_entry():
    f = {"kind": "bias", "parameter": "p", "channel": "tip_force"}
    bad = [({"kind": "gain", "parameter": "p"}, "instrument[0].kind"),
           ({"kind": "bias", "channel": "tip_force"}, "instrument[0].parameter"),
           ({"kind": "bias", "parameter": "p", "channel": "speed"}, "instrument[0].channel"),
           ({**f, "component": 3}, "instrument[0].component"),
           ({**f, "basis": "log"}, "instrument[0].basis"),
           ({**f, "value": "x"}, "instrument[0].value"),
           ({"kind": "similarity", "parameter": "p", "channel": "points", "mode": "shear"},
            "instrument[0].mode"),
           ({"kind": "series", "parameter": "p", "source": "points"}, "instrument[0].source"),
           ({"kind": "tilt", "parameter": "p", "colour": 1}, "instrument[0]")]
    for entry, where in bad:
        with pytest.raises(ForwardError) as err:
            inst.parse([entry])
        assert err.value.entry == where, err.value
    got = inst.parse([{**f, "value": "-77 mN"}, {"kind": "tilt", "parameter": "t", "value": "3 deg",
                                                 "azimuth": "90 deg"}])
    assert got[0].value == pytest.approx(-0.077, rel=1e-15) and got[1].azimuth == pytest.approx(np.pi / 2)
    with pytest.raises(ForwardError, match=r"instrument\[0\]\.value.*inconsistent units"):
        inst.parse([{**f, "value": "3 mm"}])
    with pytest.raises(ForwardError, match="array of tables"):
        inst.parse({"kind": "bias"})
    assert inst.parameter_names(inst.parse(ENTRIES)) == NAMES
    units = [inst.parameter_unit(e) for e in inst.parse(ENTRIES)]
    assert units == ["N", "N/s", "m", "m/N", "rad", "1", "rad"]


def test_every_entry_at_zero_is_exactly_nothing():
    """Value 0 (tilt: angle 0 at any azimuth) leaves drive and measurement bit-identical."""
    ref = _forward([])
    for i in range(len(ENTRIES)):
        e = dict(ENTRIES[i], value=0.0)
        got = _forward(inst.parse([e]))
        for k in ("f", "pos", "pts", "p2"):
            assert np.array_equal(got[k], ref[k]), (e["kind"], k)


def test_closed_forms():
    e = inst.parse(ENTRIES)
    f, _ = inst.drive(e, "tip_force", T, FORCE)
    # bias removed from the drive, then the drive turned by the tilt
    R, _, _ = inst._tilt(0.05, 0.7)
    unb = FORCE - np.outer(np.ones_like(T), [0, 0, 0.02]) - np.outer(5e-4 * T, [1, 0, 0])
    assert np.allclose(f, unb @ R.T, rtol=0, atol=1e-15)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-15) and np.allclose(R @ [np.cos(0.7), np.sin(0.7), 0],
                                                                         [np.cos(0.7), np.sin(0.7), 0])
    pts, _ = inst.measure(e, "points", T, PTS, {}, {})
    c, s = np.cos(0.008), np.sin(0.008)
    want = 1.01 * PTS
    want[..., :2] = want[..., :2] @ np.array([[c, -s], [s, c]]).T
    assert np.allclose(pts, want, rtol=0, atol=1e-17)
    pos, _ = inst.measure(e, "tip_position", T, POS, {}, {"tip_force": (f, {})})
    want = POS + 1e-3 * f
    want[:, 1] += 1e-4
    assert np.allclose(pos, want @ R, rtol=0, atol=1e-17)


def test_series_on_the_driving_channel_is_refused_by_drive():
    with pytest.raises(ForwardError, match="series compliance on the driving channel"):
        inst.drive(inst.parse([ENTRIES[3]]), "tip_position", T, POS)
    with pytest.raises(ForwardError, match="needs the 'tip_force' channel"):
        inst.measure(inst.parse([ENTRIES[3]]), "tip_position", T, POS, {}, {})


@pytest.mark.parametrize("name", NAMES)
def test_derivatives_match_central_differences(name):
    """Analytic derivatives of every output (skin drive, measured position incl. the series
    term's chain rule through the drive, 3D and 2D points) against central differences with
    h = 1e-6 of the parameter's scale: the outputs are polynomial or trigonometric in each
    parameter, truncation h²/6 f''' ≲ 1e-12 of the output's scale, rounding ≈ 1e-16/1e-6 =
    1e-10 of it. Tolerance 1e-8 of the output's scale per unit scale of the parameter."""
    value = {e.get("azimuth_parameter"): e["azimuth"] for e in ENTRIES if e.get("azimuth_parameter")}
    value.update({e["parameter"]: e["value"] for e in ENTRIES})
    h = 1e-6 * SCALE[name]
    base = _forward(_set(ENTRIES, name, value[name]))
    up = _forward(_set(ENTRIES, name, value[name] + h))
    dn = _forward(_set(ENTRIES, name, value[name] - h))
    for k in ("f", "pos", "pts", "p2"):
        fd = (up[k] - dn[k]) / (2 * h)
        an = base.get(f"d{k}:{name}", np.zeros_like(fd))
        tol = 1e-8 * np.abs(base[k]).max() / SCALE[name]
        assert np.abs(an - fd).max() <= tol, (k, np.abs(an - fd).max(), tol)


def test_a_displacement_driven_fe_model_refuses_a_drive_series_when_built():
    """Refused when the model is built, not after a prediction's solves have been spent."""
    from skinkit.examples import example_model
    from skinkit.fem.model import read_model
    from skinkit.forward import load

    spec = read_model(example_model("forearm_small"))
    assert spec["indenter"]["mode"] == "displacement"
    spec["effects"] = [{"name": "robot-compliance"}]
    with pytest.raises(ForwardError, match="series compliance on the driving channel 'tip_position'"):
        load(spec, workers=1)
