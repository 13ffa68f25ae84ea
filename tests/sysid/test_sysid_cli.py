"""``skinkit sysid`` and ``skinkit bench sysid`` end to end, on real files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from sysid_truth import C1_M, C2_PER_N, ROBOT, SKIN

from skinkit.cli import cli
from skinkit.sysid.simulate import simulate_record

#: the real extension-relaxation record lies beside the checkout (``../shared/data/real``)
REAL = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real" / \
    "healthy_skin_extension_relaxation.csv"


def _csv(path: Path, rec) -> Path:
    np.savetxt(path, np.column_stack([rec.time_s, rec.force_N, rec.position_m]), delimiter=",",
               header="time_s,force_N,position_m", comments="", fmt="%.12g")
    return path


@pytest.fixture(scope="module")
def wiener_csv(tmp_path_factory, total):
    rec = simulate_record(total, seed=41, wiener=(C1_M, C2_PER_N), mean_N=1.0, rms_N=0.5)
    return _csv(tmp_path_factory.mktemp("sysid") / "w.csv", rec)


def test_cli_wiener_json_and_plots(wiener_csv, tmp_path):
    r = CliRunner().invoke(cli, ["sysid", str(wiener_csv), "--model", "wiener", "--json",
                                 "--compare", "--plot", str(tmp_path / "plots")])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    for key in ("K_N_per_m", "B_Ns_per_m", "I_kg", "vaf_linear_pct", "irf_memory_s", "C1_m",
                "C2_per_N", "Is_s2", "Bs_s", "vaf_wiener_pct"):
        assert isinstance(d[key], float), key
    assert d["C1_m"] == pytest.approx(C1_M, rel=0.05)
    assert d["C2_per_N"] == pytest.approx(C2_PER_N, rel=0.05)
    assert all(Path(p).stat().st_size > 10_000 for p in d["plots"])
    assert len(d["plots"]) == 3
    vafs = {row["model"]: row["vaf_pct"] for row in d["comparison"]}
    assert vafs["wiener"] == pytest.approx(d["vaf_wiener_pct"], abs=1e-9)
    assert vafs["wiener"] > vafs["hammerstein"] and vafs["wiener"] > vafs["linear"]
    # the figures are not replaced silently: refused before any work, the files as they were
    before = {p: Path(p).read_bytes() for p in d["plots"]}
    r = CliRunner().invoke(cli, ["sysid", str(wiener_csv), "--model", "wiener",
                                 "--plot", str(tmp_path / "plots")])
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert r.exit_code == 2 and len(lines) == 1, r.output
    assert "--overwrite" in lines[0] and "sysid.png" in lines[0], r.output
    assert all(Path(p).read_bytes() == b for p, b in before.items())


def test_cli_linear_experiment_file_with_protocol(tmp_path, total):
    from skinkit.store import create_experiment

    rec = simulate_record(total, seed=42).to_robot_record(name="stochastic_normal")
    path = tmp_path / "session.h5"
    with create_experiment(path) as exp:
        exp.write_record(rec, rate_hz=2000.0)
    r = CliRunner().invoke(cli, ["sysid", str(path), "--protocol", "stochastic_normal", "--json",
                                 "--robot-mass", str(ROBOT.mass_kg), "--memory", "0.12"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert d["K_N_per_m"] == pytest.approx(SKIN.K, rel=0.03)
    assert d["I_kg"] == pytest.approx(SKIN.I, rel=0.03)
    assert d["irf_memory_s"] == pytest.approx(0.12)
    r = CliRunner().invoke(cli, ["sysid", str(path), "--protocol", "nope"])
    assert r.exit_code == 2 and "no record 'nope'" in r.stderr
    r = CliRunner().invoke(cli, ["sysid", str(path)])  # the only record is chosen
    assert r.exit_code == 0 and "VAF linear" in r.stdout


def test_cli_errors_are_one_line(tmp_path, total):
    rec = simulate_record(total, seed=43)
    rec.force_N[:] = 1.0
    bad = _csv(tmp_path / "const.csv", rec)
    r = CliRunner().invoke(cli, ["sysid", str(bad)])
    assert r.exit_code == 2
    assert r.stderr.strip().splitlines()[-1].startswith("error: force_N is constant")
    r = CliRunner().invoke(cli, ["sysid", str(tmp_path / "missing.csv")])
    assert r.exit_code == 2 and "no such file" in r.stderr


def _refused(r) -> str:
    """The one error line of a refusal (exit 2, no K, B, I on stdout)."""
    assert r.exit_code == 2, r.output
    assert "K_N_per_m" not in r.stdout and "N/m" not in r.stdout
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("error: ") and "not a broadband stochastic force test" in last
    assert "skinkit fit docs/models/extension_relaxation_qlv.toml" in last
    return last


@pytest.mark.skipif(not REAL.exists(), reason="shared real data not beside the checkout")
@pytest.mark.parametrize("args", [[], ["--axis", "x", "--json"], ["--memory", "60", "--plot", "P"]])
def test_cli_refuses_the_real_relaxation_record(tmp_path, args):
    args = [str(tmp_path / a) if a == "P" else a for a in args]
    r = CliRunner().invoke(cli, ["sysid", str(REAL), *args])
    assert "warning: NarrowbandInputWarning" in r.stderr
    assert str(REAL) in _refused(r)
    assert not (tmp_path / "P").exists()


def test_cli_refuses_a_ramp_hold_record(tmp_path):
    # an extensometer-like test at 100 Hz: ramp to 0.4 N in 8 s, hold 30 s, return, twice;
    # the position follows with a 5 s creep. Nearly all the force's variance lies below
    # 0.5 Hz (1 % of Nyquist), the defining property of a non-stochastic test.
    rate = 100.0
    one = np.concatenate([np.linspace(0, 0.4, 800), np.full(3000, 0.4), np.linspace(0.4, 0, 800)])
    f = np.tile(one, 2)
    t = np.arange(f.size) / rate
    creep = np.convolve(f, np.exp(-np.arange(2000) / (5 * rate)) / (5 * rate))[:f.size]
    y = 1e-3 * (f + creep) + 1e-7 * np.random.default_rng(0).standard_normal(f.size)
    path = tmp_path / "ramp_hold.csv"
    np.savetxt(path, np.column_stack([t, f, y]), delimiter=",", header="time_s,force_N,position_m",
               comments="", fmt="%.12g")
    _refused(CliRunner().invoke(cli, ["sysid", str(path)]))
    _refused(CliRunner().invoke(cli, ["sysid", str(path), "--model", "wiener", "--json"]))


@pytest.fixture(scope="module")
def linear_csv(tmp_path_factory, total):
    return _csv(tmp_path_factory.mktemp("sysid") / "lin.csv", simulate_record(total, seed=44))


@pytest.mark.parametrize("model", ["linear", "wiener"])
def test_cli_negative_mass_is_an_error_not_a_number(linear_csv, total, model):
    # the record's moving mass is skin + robot (40.5 g); removing 60 g of "robot" leaves
    # about -19.5 g, which the 0.3 %-level error of I at 30 dB SNR cannot make positive
    robot = 0.060
    r = CliRunner().invoke(cli, ["sysid", str(linear_csv), "--model", model, "--json",
                                 "--robot-mass", str(robot)])
    assert r.exit_code == 2, r.output
    d = json.loads(r.stdout)
    assert d["I_kg"] is None and d["I_se_kg"] is None and d["withheld"] == ["I"]
    assert d["K_N_per_m"] == pytest.approx(SKIN.K, rel=0.03)  # K and B stay physical
    (msg,) = d["errors"]
    assert "negative mass" in msg and "robot 60 g" in msg
    assert float(msg.split("=")[1].split("g")[0]) == pytest.approx(
        (total.I - robot) * 1e3, rel=0.03)
    assert r.stderr.strip().splitlines()[-1] == f"error: {msg}"
    table = CliRunner().invoke(cli, ["sysid", str(linear_csv), "--model", model,
                                     "--robot-mass", str(robot)])
    assert table.exit_code == 2
    row = next(ln for ln in table.stdout.splitlines() if ln.strip("│ ").startswith("I "))
    assert "error" in row and "-" not in row.replace("─", "")


def test_cli_irf_memory_in_sensible_units():
    from skinkit.cli.sysid import _duration

    assert _duration(0.117) == ("117", "ms")
    assert _duration(60.0) == ("60", "s")  # not "6e+04 ms"


def test_bench_sysid_json():
    r = CliRunner().invoke(cli, ["bench", "sysid", "--json", "--repeat", "1"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert d["record"]["samples"] == 10000
    assert d["wiener_identification_s"] > 0 and d["irf_full_toeplitz_lstsq_s"] > 0
    # the rank-reduced pseudo-inverse is accurate where plain least squares on an input
    # with no power above 200 Hz is not
    assert d["irf_error_svd_rel"] < 0.05 < d["irf_error_lstsq_rel"]


def test_cli_incremental(tmp_path, total):
    from skinkit.sysid import SecondOrder
    from skinkit.sysid.inputs import incremental
    from skinkit.sysid.lti import simulate
    from skinkit.sysid.simulate import SimulatedRecord, exponential

    prog = incremental("A", 3.0, 2000.0, n_steps=3, step_s=2.0, precondition_s=0.5, seed=3)
    x = simulate(SecondOrder.from_scaled(total.Is_s2, total.Bs_s), prog.force_N, 2000.0)
    y = exponential(x, C1_M, C2_PER_N)
    y = y + 1e-6 * np.random.default_rng(3).standard_normal(y.size)
    path = _csv(tmp_path / "inc.csv", SimulatedRecord(prog.force_N, y, y, 1e-6, 2000.0))
    r = CliRunner().invoke(cli, ["sysid", str(path), "--incremental", "--probe-radius", "2",
                                 "--json", "--plot", str(tmp_path)])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert [row["direction"] for row in d["increments"]] == ["up"] * 3 + ["down"] * 3
    ks = [row["K_N_per_m"] for row in d["increments"][:3]]
    assert ks == sorted(ks)
    assert all(row["E_Pa"] > 0 for row in d["increments"])
    assert len(d["hysteresis"]) == 3
    assert Path(d["plots"][0]).stat().st_size > 10_000
