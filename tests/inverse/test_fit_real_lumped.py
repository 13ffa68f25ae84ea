"""The real extension-relaxation record (``../shared/data/real``) fitted through ``skinkit fit``
with the lumped hyperelastic model and the lumped QLV model, cycles 1-2 fitted and 3-4
predicted (``--segments cycles --holdout ...``).

Nothing here is a number copied from a run: the checks are physical (stiffness positive,
relaxation times between the sampling interval and the hold durations *measured in the
record*, moduli summing below 1, the sensor zero among the forces read at rest, the elastic
curve bracketed by the forces the record shows) and statistical (finite 95 % intervals, the
AIC comparison, held-out errors present and better than predicting the cycle's mean). The
values themselves are reported (``-s`` prints them; ``record_property`` keeps them in a
junit report) and discussed in ``docs/guide/real-records.md``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.forward import read_observations

ROOT = Path(__file__).resolve().parents[2]
CSV = ROOT.parent / "shared" / "data" / "real" / "healthy_skin_extension_relaxation.csv"
MODELS = {"hyperelastic": ROOT / "docs" / "models" / "extension_relaxation_lumped.toml",
          "qlv": ROOT / "docs" / "models" / "extension_relaxation_qlv.toml"}
STEM = "healthy_skin_extension_relaxation"
FITTED = [f"{STEM}-cycle-1", f"{STEM}-cycle-2"]
HELD = [f"{STEM}-cycle-3", f"{STEM}-cycle-4"]
Z95 = 1.959964

pytestmark = [pytest.mark.needs_plugins,
              pytest.mark.skipif(not CSV.is_file(), reason="shared real data not beside the checkout")]


@pytest.fixture(scope="module")
def fits(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict]:
    out = {}
    for name, path in MODELS.items():
        d = tmp_path_factory.mktemp(name)
        r = CliRunner().invoke(cli, ["fit", str(path), str(CSV), "--segments", "cycles",
                                     "--holdout", ",".join(HELD), "--json", "--out", str(d)])
        assert r.exit_code == 0, r.output
        out[name] = json.loads((d / "fit.json").read_text())
    return out


@pytest.fixture(scope="module")
def record() -> dict[str, dict[str, float]]:
    """Per cycle, measured in the record: hold duration [s], peak force and force at the end of
    the hold [N], standard deviation of the force [N]; and the range of forces at rest."""
    obs = read_observations(CSV, axis="x", segments="cycles")
    out = {}
    for po in obs:
        t = po.channels["tip_position"].time_s
        x = po.channels["tip_position"].values[:, 0]
        f = po.channels["tip_force"].values[:, 0]
        hold = np.flatnonzero(x > x.max() - 5e-5)          # within 0.05 mm of the top (resolution 0.01 mm)
        end = f[max(hold[-1] - 100, hold[0]):hold[-1]]     # the last second of the hold
        out[po.name] = {"hold_s": float(t[hold[-1]] - t[hold[0]]), "peak_N": float(np.percentile(f, 99.9)),
                        "end_of_hold_N": float(np.median(end)), "std_N": float(np.std(f)),
                        "x_top_m": float(x.max()), "dt_s": float(np.median(np.diff(t))),
                        "noise_N": float(po.channels["tip_force"].noise[0])}
        at_rest = f[x < 5e-5]
        out[po.name]["rest_min_N"] = float(at_rest.min()) if at_rest.size else math.nan
        out[po.name]["rest_max_N"] = float(at_rest.max()) if at_rest.size else math.nan
    return out


def interval(p: dict) -> tuple[float, float]:
    return p["value"] - Z95 * p["se"], p["value"] + Z95 * p["se"]


def test_both_fits_converge_with_finite_intervals(fits, record_property) -> None:
    # The record's noise is coloured (an AR model of its rest segment: the force wanders by
    # about 13 mN at rest, neighbouring samples correlated at 0.96) and noisier under motion;
    # with it the fit has far fewer independent samples than white noise would claim. Every
    # parameter then has a finite interval, or the report names it as not determined: a term
    # the data do not support (QLV's fast term on cycles 1-2) is said, never hidden.
    for name, j in fits.items():
        assert j["converged"], f"{name}: {j['message']}"
        free = {n: p for n, p in j["parameters"].items() if p["free"]}
        problems = " ".join(str(x) for x in (j.get("identifiability") or {}).get("problems", []))
        for n, p in free.items():
            if p["se"] is None or (name == "qlv" and n in ("lumped.g1", "lumped.tau1", "lumped.g2")
                                   and n in problems):
                assert p.get("se_reason") or n in problems, (name, n, p)
                continue
            lo, hi = interval(p)
            assert math.isfinite(lo) and math.isfinite(hi) and p["se"] > 0, (name, n, p)
            record_property(f"{name}.{n}", f"{p['value']:.5g} [{lo:.5g}, {hi:.5g}] {p['unit']}")
        # the memoryless model's three parameters are all determined
        if name == "hyperelastic":
            assert all(p["se"] is not None for p in free.values())
        # the held-out cycles were not fitted
        assert set(j["residual_by_protocol"]) == set(FITTED)


def test_stiffness_is_positive_and_the_elastic_curve_is_where_the_record_puts_it(fits, record) -> None:
    for name, j in fits.items():
        P = {n: p["value"] for n, p in j["parameters"].items()}
        for n in ("lumped.a", "lumped.b"):
            assert interval(j["parameters"][n])[0] > 0, (name, n)   # the whole 95 % interval
        top = min(record[c]["x_top_m"] for c in FITTED)
        fe = P["lumped.a"] * math.expm1(P["lumped.b"] * top)        # element force at the hold [N]
        k_top = P["lumped.a"] * P["lumped.b"] * math.exp(P["lumped.b"] * top)   # tangent [N/m]
        k_zero = P["lumped.a"] * P["lumped.b"]
        assert 0 < k_zero < k_top                                   # stiffening, as skin does
        peak = max(record[c]["peak_N"] for c in FITTED) - P["offset.x"]
        relaxed = [record[c]["end_of_hold_N"] - P["offset.x"] for c in FITTED]
        if name == "hyperelastic":
            # a memoryless element fitted to relaxing holds lies between relaxed and peak force
            assert min(relaxed) <= fe <= peak
        else:
            ginf = 1 - P["lumped.g1"] - P["lumped.g2"]
            # fully relaxed the element is below the peak and near the relaxed holds; the
            # instantaneous element lies above the relaxed force. (Under the coloured noise
            # the ramps weigh little — the sensor is two to three times noisier while the pad
            # moves — so the instantaneous curve is not held to the first peak.)
            assert 0 < ginf * fe <= peak and fe >= min(relaxed)
        print(f"\n{name}: element force at {top * 1e3:.2f} mm {fe:.3g} N, tangent stiffness {k_zero:.3g} N/m "
              f"at 0 -> {k_top:.3g} N/m at the hold")


def test_relaxation_times_lie_between_the_sampling_interval_and_the_holds(fits, record) -> None:
    P = fits["qlv"]["parameters"]
    g = [P["lumped.g1"]["value"], P["lumped.g2"]["value"]]
    assert all(0 <= gi < 1 for gi in g) and sum(g) < 1
    dt = record[FITTED[0]]["dt_s"]
    shortest_hold = min(record[c]["hold_s"] for c in FITTED)
    assert shortest_hold > 30                                    # README: holds of about 45-60 s
    # the term that carries the relaxation (the larger modulus) is determined: its whole 95 %
    # interval is a time the record can show, longer than a sample and shorter than the holds
    main = max((1, 2), key=lambda i: P[f"lumped.g{i}"]["value"])
    lo, hi = interval(P[f"lumped.tau{main}"])
    assert 10 * dt < lo and hi < shortest_hold, (main, lo, hi, shortest_hold)
    assert P[f"lumped.g{main}"]["value"] > 0.1                    # the holds relax by a tenth or more
    print(f"\nqlv: tau = {P['lumped.tau1']['value']:.3g} s, {P['lumped.tau2']['value']:.3g} s; "
          f"holds of the fitted cycles {[round(record[c]['hold_s'], 1) for c in FITTED]} s")


def test_the_sensor_zero_is_among_the_forces_read_at_rest(fits, record) -> None:
    lo = min(record[c]["rest_min_N"] for c in record if math.isfinite(record[c]["rest_min_N"]))
    hi = max(record[c]["rest_max_N"] for c in record if math.isfinite(record[c]["rest_max_N"]))
    for name, j in fits.items():
        # and below zero, as the record reads at its start (README: about -0.077 N)
        assert lo <= j["parameters"]["offset.x"]["value"] <= min(hi, 0.0), name


def test_aic_and_held_out_errors_are_reported_for_both_models(fits, record, record_property) -> None:
    rows = []
    for name, j in fits.items():
        held = j["held_out"]
        assert set(held) == set(HELD), name
        for c in HELD:
            # noise-normalised RMS: finite, and better than predicting the cycle's own mean
            # (its standard deviation in noise levels): the model carries over to unseen cycles
            assert 0 < held[c] < record[c]["std_N"] / record[c]["noise_N"], (name, c, held[c])
        k = sum(p["free"] for p in j["parameters"].values())
        rows.append((name, k, j["aic"], j["aicc"], j["chi2_per_dof"], held[HELD[0]], held[HELD[1]]))
    for r in rows:
        record_property(f"{r[0]}.aic", r[2])
        print(f"\n{r[0]}: {r[1]} free, AIC {r[2]:.6g}, AICc {r[3]:.6g}, chi2/dof {r[4]:.4g}, "
              f"held out rms {r[5]:.3g} and {r[6]:.3g} noise levels")
    d_aic = fits["qlv"]["aic"] - fits["hyperelastic"]["aic"]
    record_property("delta_aic_qlv_minus_hyperelastic", d_aic)
    print(f"\nAIC(QLV) - AIC(hyperelastic) = {d_aic:.6g}")
    # the force relaxes by ~0.1 N (tens of noise levels) in every hold, which a memoryless
    # element cannot follow: the relaxation terms must pay for their 4 extra parameters
    # (a difference beyond 2 x 4) by a wide margin
    assert d_aic < -8
