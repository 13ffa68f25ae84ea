"""Residual diagnostics: a right model leaves a white residual; a wrong one shows where."""

from __future__ import annotations

import numpy as np
import pytest
from sysid_truth import C1_M, C2_PER_N

from skinkit.sysid import SysidError, identify_hammerstein, identify_wiener
from skinkit.sysid.diagnostics import compare, diagnose, residual_diagnostics
from skinkit.sysid.plots import plot_identification, plot_incremental, plot_residuals
from skinkit.sysid.simulate import simulate_record


@pytest.fixture(scope="module")
def wiener_case(total):
    rec = simulate_record(total, seed=31, wiener=(C1_M, C2_PER_N), mean_N=1.0, rms_N=0.5)
    w = identify_wiener(rec.force_N, rec.position_m, 2000.0)
    return rec, w


def test_wiener_residual_white_linear_residual_not(wiener_case):
    rec, w = wiener_case
    b = w.linear.burn_in
    dw = diagnose(w, rec.force_N, rec.position_m, 2000.0, b)
    dl = diagnose(w.linear, rec.force_N, rec.position_m, 2000.0, b)
    # white noise leaves ~5 % of lags outside the 95 % band; allow 3x for the few
    # correlated lags that a finite-memory model leaves
    assert dw.whiteness_outside < 0.15
    assert dl.whiteness_outside > 0.5
    assert dw.crosscorr_outside < 0.15
    # the missing nonlinearity shows at the output extremes: the linear model's VAF in the
    # top amplitude band is below the Wiener model's
    assert dl.vaf_by_amplitude_pct[-1] < dw.vaf_by_amplitude_pct[-1]
    assert dl.vaf_pct < dw.vaf_pct
    assert dw.autocorr[dw.lags_s == 0][0] == pytest.approx(1.0)
    d = dw.to_dict()
    assert len(d["vaf_by_band_pct"]) == len(d["band_edges_hz"]) - 1


def test_band_vaf_is_exact_partition():
    rng = np.random.default_rng(0)
    y = rng.standard_normal(4000)
    d = residual_diagnostics(y, y, y, 1000.0)
    assert np.allclose(d.vaf_by_band_pct, 100.0)
    assert np.allclose(d.vaf_by_amplitude_pct, 100.0)
    with pytest.raises(SysidError, match="differ in length"):
        residual_diagnostics(y, y, y[:-1], 1000.0)


def test_compare_and_plots(wiener_case, tmp_path):
    rec, w = wiener_case
    h = identify_hammerstein(rec.force_N, rec.position_m, 2000.0, linear=w.linear)
    rows = compare({"linear": w.linear, "wiener": w, "hammerstein": h}, rec.force_N,
                   rec.position_m, 2000.0, w.linear.burn_in)
    vafs = {r["model"]: r["vaf_pct"] for r in rows}
    assert vafs["wiener"] > vafs["hammerstein"] >= vafs["linear"] - 0.01
    for model, name in ((w, "w.png"), (w.linear, "l.png"), (h, "h.png")):
        out = plot_identification(model, rec.force_N, rec.position_m, tmp_path / name)
        assert out.stat().st_size > 10_000
    d = diagnose(w, rec.force_N, rec.position_m, 2000.0, w.linear.burn_in)
    assert plot_residuals(d, tmp_path / "r.png").stat().st_size > 10_000
    table = [{"direction": "up", "position_mean_m": 1e-3, "K_N_per_m": 1.0, "I_kg": 1.0,
              "B_Ns_per_m": 1.0, "vaf_linear_pct": 90.0}]
    assert plot_incremental(table, tmp_path / "i.png").stat().st_size > 10_000
