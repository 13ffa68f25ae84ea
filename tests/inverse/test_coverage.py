"""Coverage of the fit's 95 % intervals on virtual sessions of known truth.

The lumped relaxation case runs in full here (100 seeds, 4 free parameters: 400 parameter-seed
pairs). Under exact coverage the inside count is binomial(400, 0.95) if pairs were independent:
mean 380, sd 4.4; the acceptance band 90-99 % is 360-396 pairs, and the probability of falling
outside it is :func:`outside_band_probability` (1.6e-5, checked in the test). Pairs within a
seed are correlated (a and b strongly), which widens the count's spread; the per-parameter RMS
of z = (estimate − truth)/se over 100 independent seeds is a sharper check: RMS² ~ χ²₁₀₀/100, so
RMS outside [0.7, 1.3] has probability below 1e-5 for honest intervals.

The FE cases are reduced to what CI affords (a couple of seeds on small meshes): the harness
runs, the intervals are finite, and the z-scores are O(1). Their full 20-seed coverage is the
benchmark ``skinkit bench coverage``.
"""

from __future__ import annotations

import math

import pytest

from skinkit.bench.coverage import gel_spec, lumped_spec, twopad_spec
from skinkit.forward import load
from skinkit.inverse.coverage import (
    CoverageError,
    LabSessions,
    coverage,
    expected_range,
    outside_band_probability,
    perturbed_start,
    z_of_level,
)
from skinkit.schemas import Channel, Observations, ProtocolObservations

pytestmark = pytest.mark.needs_plugins


@pytest.fixture(scope="module")
def lumped():
    spec, free = lumped_spec()
    lab = LabSessions(spec)
    return lab, load(lab.model_spec), free


def test_binomial_helpers():
    assert z_of_level(0.95) == pytest.approx(1.959964, abs=1e-6)
    from scipy.stats import binom
    lo, hi = expected_range(400, 0.95)
    assert lo < 380 < hi
    assert binom.cdf(hi, 400, 0.95) - binom.cdf(lo - 1, 400, 0.95) >= 0.95
    # the band is meaningful at 400 pairs, not at 20
    assert outside_band_probability(400) < 1e-3
    assert outside_band_probability(20) > 0.2


def test_lumped_coverage_100_seeds(lumped):
    lab, model, free = lumped
    assert outside_band_probability(400) < 1e-4          # 1.6e-5: a failure here is not bad luck
    res = coverage(model, lab, free, 100, start=perturbed_start(model, free))
    assert res["failed"] == 0 and res["pairs"] == 400
    assert 0.90 <= res["coverage"] <= 0.99, res["coverage"]
    for n, p in res["per_parameter"].items():
        assert 0.7 < p["rms_z"] < 1.3, (n, p)
        assert abs(p["mean_z"]) < 0.4, (n, p)             # 4 sd of a mean of 100 standard normals
    # the noise model the fit uses is the one the data were made with: chi2/dof = 1 within
    # its sampling spread (62,000 samples: sd 0.006)
    assert abs(res["chi2_per_dof_mean"] - 1) < 0.01


def _rescaled(make, factor):
    """Sessions whose declared noise is ``factor`` times the noise they were made with."""
    def inner(seed):
        obs = make(seed)
        out = {}
        for po in obs:
            ch = {c: Channel(c, v.time_s, v.values, v.valid, v.noise * factor, v.noise_source, v.reference,
                             v.reference_frame) for c, v in po.channels.items()}
            out[po.name] = ProtocolObservations(po.protocol, ch)
        return Observations(out, None, obs.source)
    return inner


def test_lumped_inflated_intervals_are_caught(lumped):
    """The test has power: declaring twice the true noise doubles every interval (the fit does not
    deflate its covariance when chi2/dof < 1), so a pair falls outside only beyond 3.92 true
    standard errors (probability 1e-4), and RMS z is 0.5. Over 40 seeds RMS z scatters by
    0.5/√(2·40) = 0.056: the bound 0.65 is 2.7 of those above it (a false failure below 0.4 %),
    and honest intervals (RMS z 1) lie 6 below it."""
    lab, model, free = lumped
    res = coverage(model, _rescaled(lab, 2.0), free, 40)
    assert res["coverage"] > 0.99
    for p in res["per_parameter"].values():
        assert p["rms_z"] < 0.65


def test_drive_noise_is_errors_in_variables(lumped):
    """With the drive sensor's noise on the drive the session leaves the objective's noise model;
    on this lumped truth the position noise (1 µm) against the force noise through the
    element's stiffness is small, so the estimate moves by a fraction of its interval."""
    lab0, model, free = lumped
    spec, _ = lumped_spec()
    noisy = LabSessions(spec, drive_noise=True)
    a = coverage(model, lab0, free, [3])["per_seed"][0]
    b = coverage(model, noisy, free, [3])["per_seed"][0]
    for n in free:
        assert abs(a["estimates"][n] - b["estimates"][n]) < 0.5 * a["se"][n]


def test_bad_inputs(lumped):
    lab, model, free = lumped
    with pytest.raises(CoverageError, match="no seed"):
        coverage(model, lab, free, [])
    with pytest.raises(CoverageError, match="no parameter"):
        coverage(model, lab, ["lumped.nope"], 2)
    with pytest.raises(CoverageError, match="level"):
        coverage(model, lab, free, 2, level=1.5)


def _small_fe(case_spec, **geometry):
    spec, free = case_spec()
    spec["geometry"].update(geometry)
    return spec, free


@pytest.mark.parametrize("case", ["gel", "twopad"])
def test_fe_harness_reduced(case):
    """Two seeds on the smallest meshes: finite intervals, O(1) z-scores, chi2/dof near 1."""
    if case == "gel":
        spec, free = _small_fe(gel_spec, n_inner=1, n_ring=1)
        spec["layers"][0]["elements"] = 2
    else:
        spec, free = _small_fe(twopad_spec, n_gap=3, n_outer=1, n_side=1)
    # the fit's statistics where the model is exact: the truth on the model's mesh (a truth on its
    # own mesh and the carried model error: test_approximation_error)
    lab = LabSessions(spec, mesh="shared")
    model = load(lab.model_spec, workers=1)
    try:
        res = coverage(model, lab, free, 2)
    finally:
        if hasattr(model, "close"):
            model.close()
    assert res["failed"] == 0
    for rec in res["per_seed"]:
        for n in free:
            assert math.isfinite(rec["se"][n]) and rec["se"][n] > 0
            assert abs(rec["z"][n]) < 5                    # |z| > 5 has probability 6e-7 per pair
        # >= 10^4 residuals: chi2/dof has sd <= 0.014 under the noise model
        assert abs(rec["chi2_per_dof"] - 1) < 0.07


def test_coverage_bench_refuses_an_unknown_mesh_mode():
    from skinkit.bench.coverage import run_case
    from skinkit.errors import SkinkitError

    with pytest.raises(SkinkitError, match="--mesh: expected one of shared, own"):
        run_case("lumped", 1, mesh="fine")


def test_the_summary_says_when_the_truth_is_not_converged(monkeypatch):
    """A truth whose own error bound reaches a noise level is flagged (the intervals are then
    judged against the truth's mesh); one below it is not."""
    import skinkit.bench.coverage as cov

    def res(bound):
        case = {"note": "n", "truth_mesh": {"truth_unknowns": 10, "model_unknowns": 1, "factor": 2,
                                            "discretisation": {"points": {"truth_over_noise": bound}}},
                "model_error": {"largest_over_noise": 3.0}}
        return {"mesh": "own", "cases": {"twopad": case}}

    monkeypatch.setattr(cov, "_line", lambda r: "row")     # the table row is another test's
    flagged = cov.summary_lines(res(2.15))
    clean = cov.summary_lines(res(0.5 * cov.UNCONVERGED_TRUTH))
    assert any("not converged" in x and "2.15" in x for x in flagged)
    assert not any("not converged" in x for x in clean)
