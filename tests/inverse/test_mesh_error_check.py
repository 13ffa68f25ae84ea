"""The figures of the check of the carried model error against a truth of its own
(``skinkit bench mesh-error``), on constructed errors whose answers are known exactly: a truth
error that is a·d has ratio a everywhere, per point and per band; one whose ratio grows with the
distance from the probe shows it band by band, which one ratio per band cannot fit."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit.bench import mesh_error


def _field(P: int = 40, F: int = 6, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    d = 5.0 * rng.standard_normal((P, F, 3))
    ang = rng.uniform(0, 2 * np.pi, P)
    rad = np.linspace(3e-3, 8e-3, P)
    ref = np.stack([rad * np.cos(ang), rad * np.sin(ang), np.zeros(P)], axis=1)
    return d, ref


def test_a_truth_error_along_the_refinement_has_its_ratio_everywhere():
    d, ref = _field()
    out = mesh_error._points(d, 1.3 * d, ref)
    pp = out["ratio_per_point"]
    assert pp["p10"] == pytest.approx(1.3) and pp["p90"] == pytest.approx(1.3)
    assert len(out["bands"]) == mesh_error.BANDS
    for b in out["bands"]:
        assert b["ratio"] == pytest.approx(1.3)
        assert b["rms_error"] == pytest.approx(1.3 * b["rms_refined"])
    assert mesh_error._ratio(d, 1.3 * d) == pytest.approx(1.3)


def test_a_ratio_that_changes_with_distance_shows_band_by_band():
    d, ref = _field(P=80)
    rad = np.hypot(ref[:, 0], ref[:, 1])
    a = np.interp(rad, [3e-3, 8e-3], [1.5, -0.5])      # near the probe 1.5, far -0.5
    out = mesh_error._points(d, a[:, None, None] * d, ref)
    ratios = [b["ratio"] for b in out["bands"]]
    assert all(x > y for x, y in zip(ratios, ratios[1:], strict=False)), ratios
    assert ratios[0] > 1.0 and ratios[-1] < 0.0
    pp = out["ratio_per_point"]
    assert pp["p10"] < 0.0 < 1.0 < pp["p90"]


def test_the_summary_names_every_figure():
    d, ref = _field()
    row = {"protocol": "normal_indentation", "channel": "points", "samples": d.size, "rms_error": 2.0,
           "rms_refined": 1.5, "rms_miss": 0.5, "ratio": 1.3, "chi2_per_sample": 0.2,
           **mesh_error._points(d, 1.3 * d, ref)}
    res = {"cases": {"gel": {"truth_factor": 2, "truth_mesh": {"truth_unknowns": 100, "model_unknowns": 10},
                             "ratio_range": [4 / 3, 2.0], "ratio_assumed": 5 / 3, "channels": [row]}},
           "truth_factor": 2}
    text = "\n".join(mesh_error.summary_lines(res))
    for needle in ("gel: truth 100 unknowns (2x", "ratio assumed 1.667 in [1.333, 2.000]", "points",
                   "ratio per point and component: 10 % 1.30", "by distance from the probe"):
        assert needle in text, (needle, text)


def test_the_truths_own_error_is_its_largest_channel_bound():
    from skinkit.lab.truth_mesh import largest_truth_error

    mesh = {"discretisation": {"tip_force": {"truth_over_noise": 3.6}, "points": {"truth_over_noise": 6.5},
                               "drive": {"truth_over_noise": None}}}
    assert largest_truth_error(mesh) == 6.5
    assert largest_truth_error({}) is None
