"""Schemas: shapes, units and values are checked on construction; errors name the field."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skinkit.errors import SchemaError, UnitError
from skinkit.schemas import (
    CameraModel,
    CameraRig,
    Channel,
    EffectScore,
    FitResult,
    GapReport,
    ImageSequence,
    Parameter,
    ParameterSet,
    Protocol,
    RobotRecord,
    SurfaceProfile,
    SurfaceTrack,
)
from skinkit.units import Q, from_si, to_si


def _record(n: int = 10, **kw):
    return RobotRecord(time_s=np.arange(n) * 1e-3, **kw)


def test_robot_record_ok_and_rate():
    r = _record(100, tip_force=np.zeros((100, 3)), tip_position=np.zeros((100, 3)))
    assert r.channels == ["tip_position", "tip_force"]
    assert r.rate_hz == pytest.approx(1000.0)
    assert r.flags.dtype == np.uint32 and r.flags.shape == (100,)
    assert r.is_uniform()


@pytest.mark.parametrize("field,value,needle", [
    ("tip_force", np.zeros((10, 2)), "RobotRecord.tip_force"),
    ("tip_position", np.zeros((9, 3)), "RobotRecord.tip_position"),
    ("motor_current", np.zeros(10), "RobotRecord.motor_current"),
    ("flags", -np.ones(10), "RobotRecord.flags"),
    ("flags", np.zeros(10) + 0.5, "RobotRecord.flags"),
])
def test_robot_record_wrong_shape_names_field(field, value, needle):
    with pytest.raises(SchemaError) as e:
        _record(10, **{field: value})
    assert needle in str(e.value) and "\n" not in str(e.value)
    assert e.value.field == needle


def test_robot_record_time_must_increase():
    with pytest.raises(SchemaError, match="time_s.*strictly increasing"):
        RobotRecord(time_s=[0.0, 1.0, 1.0])
    with pytest.raises(SchemaError, match="non-finite"):
        RobotRecord(time_s=[0.0, np.nan])


def test_units_convert_and_refuse():
    r = _record(3, tip_position=Q(np.ones((3, 3)), "mm"), tip_force=Q(np.ones((3, 3)), "mN"))
    assert np.allclose(r.tip_position, 1e-3) and np.allclose(r.tip_force, 1e-3)
    with pytest.raises(UnitError, match="RobotRecord.tip_position.*'N' is not a unit of 'm'"):
        _record(3, tip_position=Q(np.ones((3, 3)), "N"))
    with pytest.raises(UnitError, match="unknown unit 'furlong'"):
        _record(3, tip_force=Q(np.ones((3, 3)), "furlong"))
    assert to_si(2.0, "kPa", "Pa") == pytest.approx(2000.0)
    assert from_si(0.002, "mm") == pytest.approx(2.0)


def test_protocol_validation_and_roundtrip():
    p = Protocol("normal_indentation", kind="trajectory", parameters={"amplitude": 7.5e-4, "freq": 0.1},
                 units={"amplitude": "m", "freq": "Hz"}, duration_s=30.0)
    assert Protocol.from_dict(p.to_dict()) == p
    with pytest.raises(SchemaError, match="Protocol.kind"):
        Protocol("x", kind="dance")
    with pytest.raises(SchemaError, match="Protocol.name"):
        Protocol("")
    with pytest.raises(SchemaError, match=r"Protocol.parameters\['a'\].*not finite"):
        Protocol("x", parameters={"a": math.nan})
    with pytest.raises(SchemaError, match="unknown parameter 'b'"):
        Protocol("x", parameters={"a": 1}, units={"b": "m"})
    with pytest.raises(SchemaError, match="unknown key"):
        Protocol.from_dict({"name": "x", "colour": "red"})


def _camera(name="c0", **kw):
    args = dict(name=name, K=[[2000, 0, 320], [0, 2000, 240], [0, 0, 1]], distortion=np.zeros(5),
                R=np.eye(3), t=[0, 0, 0.2], image_size=(640, 480))
    args.update(kw)
    return CameraModel(**args)


def test_camera_and_rig():
    rig = CameraRig((_camera("a"), _camera("b")))
    assert rig["b"].name == "b" and len(rig) == 2
    assert rig[0].P.shape == (3, 4)
    assert np.allclose(rig[0].centre, [0, 0, -0.2])
    with pytest.raises(SchemaError, match=r"CameraModel\['c0'\].R.*not a rotation"):
        _camera(R=np.diag([1, 1, -1.0]))
    with pytest.raises(SchemaError, match=r"CameraModel\['c0'\].distortion.*length 3"):
        _camera(distortion=[0, 0, 0])
    with pytest.raises(SchemaError, match=r"CameraModel\['c0'\].K"):
        _camera(K=np.eye(2))
    with pytest.raises(SchemaError, match="duplicate camera name"):
        CameraRig((_camera("a"), _camera("a")))
    with pytest.raises(KeyError, match="camera 'z' is not in the rig"):
        rig["z"]


def test_image_sequence():
    seq = ImageSequence("s", np.zeros((2, 4, 8, 10), np.uint8), ("a", "b", "c", "d"), [0.0, 0.1])
    assert seq.image_size == (10, 8) and seq.n_frames == 2
    with pytest.raises(SchemaError, match="camera_names.*3 names for 4 cameras"):
        ImageSequence("s", np.zeros((2, 4, 8, 10), np.uint8), ("a", "b", "c"), [0.0, 0.1])
    with pytest.raises(SchemaError, match="ImageSequence.time_s"):
        ImageSequence("s", np.zeros((2, 1, 8, 10), np.uint8), ("a",), [0.0, 0.1, 0.2])
    with pytest.raises(SchemaError, match="ImageSequence.frames.*dtype"):
        ImageSequence("s", np.zeros((2, 1, 8, 10), np.int8), ("a",), [0.0, 0.1])


def test_surface_profile_and_track():
    prof = SurfaceProfile(points=np.zeros((5, 3)), quality=np.ones(5))
    assert prof.n_points == 5
    with pytest.raises(SchemaError, match="SurfaceProfile.quality"):
        SurfaceProfile(points=np.zeros((5, 3)), quality=np.ones(4))
    pts = np.zeros((4, 3, 3))
    valid = np.ones((4, 3), bool)
    pts[1, 2] = np.nan
    valid[1, 2] = False
    tr = SurfaceTrack(points=pts, valid=valid, time_s=[0, 1, 2])
    assert tr.n_points == 4 and tr.n_frames == 3
    with pytest.raises(SchemaError, match="SurfaceTrack.points.*valid is not finite"):
        SurfaceTrack(points=pts, valid=np.ones((4, 3), bool), time_s=[0, 1, 2])
    with pytest.raises(SchemaError, match="SurfaceTrack.valid"):
        SurfaceTrack(points=pts, valid=np.ones((4, 2), bool), time_s=[0, 1, 2])


def test_parameter_set():
    ps = ParameterSet([Parameter("skin.mu", 10, "kPa", 1, 100),
                       Parameter("nu", 0.45, "1", 0, 0.5, free=False),
                       Parameter("k2", 5.0, lower=0.0)])
    assert ps["skin.mu"] == pytest.approx(1e4) and ps.param("skin.mu").unit == "Pa"
    assert ps.free_names == ["skin.mu", "k2"]
    ps2 = ps.with_free_vector([2e4, 3.0])
    assert ps2["skin.mu"] == 2e4 and ps2["nu"] == 0.45
    assert ParameterSet.from_list(ps.to_list()) == ps
    lo, hi = ps.free_bounds()
    assert lo.tolist() == [1e3, 0.0] and hi[1] == math.inf
    with pytest.raises(SchemaError, match=r"Parameter\['skin.mu'\].value.*outside its bounds"):
        ps.with_free_vector([1e6, 3.0])
    with pytest.raises(SchemaError, match="duplicate parameter name"):
        ParameterSet([Parameter("a", 1), Parameter("a", 2)])
    with pytest.raises(SchemaError, match=r"Parameter\['kappa'\].value"):
        Parameter("kappa", 0.4, "1", 0, 1 / 3)
    with pytest.raises(SchemaError, match="expected 2 values"):
        ps.with_free_vector([1.0])


def test_fit_result_and_gap_report_roundtrip():
    ps = ParameterSet([Parameter("K", 1450, "N/m", 0, 1e5)])
    fit = FitResult("kelvin-voigt", ps, objective=1e-9, n_evaluations=12, residual_rms_m=1e-5,
                    covariance=[[4.0]])
    back = FitResult.from_dict(fit.to_dict())
    assert back.parameters == ps and back.covariance.shape == (1, 1)
    with pytest.raises(SchemaError, match="FitResult.covariance"):
        FitResult("m", ps, objective=0.0, covariance=np.eye(2))


def test_strict_json_says_why_a_number_is_null():
    """An infinite bound or standard error is written as null with its reason beside it, and a
    stored fit reads back infinite."""
    from skinkit import jsonio
    from skinkit.inverse import fit_json

    ps = ParameterSet([Parameter("skin.k1", 2.0, "Pa", lower=0.0),
                       Parameter("skin.k2", 0.5, lower=0.0, upper=1.0)])
    fit = FitResult("m", ps, objective=1.0, se={"skin.k1": math.inf, "skin.k2": 0.01},
                    identifiability={"metrics": {"cond_H": math.inf}, "identifiable": {"skin.k1": False}})
    stored = jsonio.loads_strict(jsonio.dumps(fit.to_dict()))
    assert stored["se"]["skin.k1"] is None and "undetermined" in stored["se_reason"]["skin.k1"]
    assert "skin.k2" not in stored["se_reason"]
    assert stored["parameters"][0]["upper"] is None and stored["parameters"][0]["upper_reason"] == "unbounded"
    back = FitResult.from_dict(stored)
    assert back.se == {"skin.k1": math.inf, "skin.k2": 0.01} and back.parameters == ps
    j = jsonio.loads_strict(jsonio.dumps(fit_json(fit)))
    k1 = j["parameters"]["skin.k1"]
    assert k1["se"] is None and "undetermined" in k1["se_reason"]
    assert k1["upper"] is None and k1["upper_reason"] == "unbounded" and "lower_reason" not in k1
    assert "se_reason" not in j["parameters"]["skin.k2"] and j["parameters"]["skin.k2"]["unit"] == "1"
    metrics = j["identifiability"]["metrics"]
    assert metrics["cond_H"] is None and "singular" in metrics["cond_H_reason"]
    assert "cond_H_reason" not in fit.identifiability["metrics"]   # the result itself is left as it was


def test_gap_report_roundtrip_and_checks():
    cands = [EffectScore("prestress", score=250.0, p_value=1e-50, dof=2, refitted=True, delta_aic=-240.0,
                         shrinkage=0.8, parameters={"prestress.l1": {"value": 1.1, "se": 0.01}},
                         not_separable_from=["fibres"], extra={"sensitivity": {"prestress.l1": "analytic"}}),
             EffectScore("fibres", score=3e4, p_value=0.0, dof=1, delta_aic=float("nan"))]
    gap = GapReport("m", "s.h5", fit={"parameters": {"skin.c": 1e4}, "chi2_per_dof": 1.7, "n_forward": 9},
                    gap={"significant": True, "chi2_per_dof": 1.7, "cells": []}, candidates=cands,
                    named=["prestress"], shrinkage={"overall": 0.8, "held_out": None, "cells": []},
                    extra={"messages": ["x"], "point_map_after": {"p": np.array([1.0, np.nan])}})
    assert gap.best.effect == "prestress" and gap.significant
    d = gap.to_dict()
    assert list(d)[:7] == ["model", "session", "fit", "gap", "candidates", "named", "shrinkage"]
    assert d["candidates"][1]["delta_aic"] is None        # NaN is not JSON: null
    assert d["point_map_after"]["p"] == [1.0, None]
    assert d["candidates"][0]["sensitivity"] == {"prestress.l1": "analytic"}
    import json
    back = GapReport.from_dict(json.loads(json.dumps(d, allow_nan=False)))
    assert back.named == ["prestress"] and back.candidates[0].not_separable_from == ["fibres"]
    assert back.extra["messages"] == ["x"] and back.candidates[0].extra == cands[0].extra
    with pytest.raises(SchemaError, match=r"GapReport.named.*'slip'"):
        GapReport("m", candidates=cands, named=["slip"])
    with pytest.raises(SchemaError, match=r"shrinkage.overall.*cannot exceed 1"):
        GapReport("m", shrinkage={"overall": 1.5})
    with pytest.raises(SchemaError, match=r"EffectScore\['x'\].p_value"):
        EffectScore("x", score=1.0, p_value=2.0)
    with pytest.raises(SchemaError, match="GapReport.extra"):
        GapReport("m", extra={"named": []})


def test_unwhiten_inverts_whiten_and_whitening_makes_reference_noise_white():
    """A track whose reference is its frame 0: residuals over the other m frames share that
    frame's noise, covariance σ²(I + 11ᵀ); whiten maps them to independent standard normals
    and unwhiten is its exact inverse (masked entries stay 0)."""
    rng = np.random.default_rng(3)
    P, T = 400, 6
    ref_noise = rng.standard_normal((P, 1, 3))
    frame_noise = rng.standard_normal((P, T, 3))
    r = frame_noise - ref_noise                      # what a residual against a noisy reference sees
    ch = Channel("points", np.arange(T, dtype=float), np.zeros((P, T, 3)), noise=1.0,
                 reference=np.zeros((P, 3)), reference_frame=0)
    m = ch.fit_mask()
    w = ch.whiten(r, m)
    assert not m[:, 0].any() and np.all(w[:, 0] == 0)
    cov = np.cov(w[:, 1:, 0].T)                      # (T-1, T-1): white within 4 standard errors
    assert np.abs(cov - np.eye(T - 1)).max() < 4 * np.sqrt(2 / P)
    a = rng.standard_normal((P, T, 3))
    np.testing.assert_allclose(ch.whiten(ch.unwhiten(a, m), m), np.where(m, a, 0.0), atol=1e-12)
    np.testing.assert_allclose(ch.unwhiten(ch.whiten(a, m), m), np.where(m, a, 0.0), atol=1e-12)
    exact = Channel("points", np.arange(T, dtype=float), np.zeros((P, T, 3)), noise=1.0,
                    reference=np.zeros((P, 3)))
    assert exact.unwhiten(a, exact.fit_mask()) is a


def test_whitening_with_a_standard_error_per_position():
    """A tracker's error grows with the deformation: frame f of point p has its own σ s_pf,
    the reference frame its floor σ s_p0. Residuals normalised by :meth:`Channel.sigma` and
    whitened are independent standard normals (covariance I + vvᵀ, v = s_p0 / s_pf, undone
    exactly), and unwhiten is still the exact inverse."""
    rng = np.random.default_rng(5)
    P, T = 4000, 5
    scale = np.ones((P, T, 3))
    scale[:, 1:] = 1.0 + 9.0 * rng.random((P, T - 1, 3))          # 1-10x the floor
    ref_noise = rng.standard_normal((P, 1, 3))
    r = scale * rng.standard_normal((P, T, 3)) - ref_noise
    ch = Channel("points", np.arange(T, dtype=float), np.zeros((P, T, 3)), noise=2e-6,
                 reference=np.zeros((P, 3)), reference_frame=0, noise_scale=scale)
    np.testing.assert_allclose(ch.sigma(), 2e-6 * scale)
    m = ch.fit_mask()
    w = ch.whiten(r * 2e-6 / ch.sigma(), m)
    cov = np.cov(w[:, 1:, 1].T)
    assert np.abs(cov - np.eye(T - 1)).max() < 4 * np.sqrt(2 / P)
    a = rng.standard_normal((P, T, 3))
    np.testing.assert_allclose(ch.whiten(ch.unwhiten(a, m), m), np.where(m, a, 0.0), atol=1e-12)
    flat = Channel("points", np.arange(T, dtype=float), np.zeros((P, T, 3)), noise=2e-6,
                   reference=np.zeros((P, 3)), reference_frame=0, noise_scale=np.ones((P, T, 3)))
    same = Channel("points", np.arange(T, dtype=float), np.zeros((P, T, 3)), noise=2e-6,
                   reference=np.zeros((P, 3)), reference_frame=0)
    np.testing.assert_allclose(flat.whiten(a, m), same.whiten(a, m), atol=1e-14)
    with pytest.raises(SchemaError, match="noise_scale"):
        Channel("points", np.arange(T, dtype=float), np.zeros((P, T, 3)), noise=2e-6,
                noise_scale=np.zeros((P, T, 3)))
