"""Splitting records into loading cycles (:mod:`skinkit.forward.segments`): synthetic records
whose cycles and rests are known by construction, noise and spikes on the drive, the errors,
and the real extension-relaxation record (four cycles)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from skinkit.errors import SchemaError
from skinkit.forward import load, read_observations
from skinkit.forward.segments import cycle_cuts, split
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

ROOT = Path(__file__).resolve().parents[2]
CSV = ROOT.parent / "shared" / "data" / "real" / "healthy_skin_extension_relaxation.csv"
DT = 0.01
AMP = 0.008          # [m] 8 mm of pull


Cycle = tuple[float, float, float, float]


def programme(cycles: list[Cycle], lead: float = 3.0) -> tuple[np.ndarray, np.ndarray, list]:
    """A drive ``(t, u)`` at 100 Hz: after ``lead`` s of rest, per cycle (ramp s, hold s,
    return level as a fraction of AMP, dwell s at that level); and each cycle's rest interval
    [s, s] after it (the dwell, or the turning point)."""
    knots_t, knots_u = [0.0, lead], [0.0, 0.0]
    rests = []
    for ramp, hold, back, dwell in cycles:
        t = knots_t[-1]
        knots_t += [t + ramp, t + ramp + hold, t + 2 * ramp + hold, t + 2 * ramp + hold + dwell]
        knots_u += [AMP, AMP, back * AMP, back * AMP]
        rests.append((t + 2 * ramp + hold, t + 2 * ramp + hold + dwell))
    t = np.arange(0.0, knots_t[-1] + 1e-9, DT)
    return t, np.interp(t, knots_t, knots_u), rests


def session(t: np.ndarray, u: np.ndarray, axis: int = 0, noise: float = 2e-6, name: str = "pull",
            points: bool = False) -> Observations:
    pos = np.full((t.size, 3), np.nan)
    pos[:, axis] = u
    force = np.full((t.size, 3), np.nan)
    force[:, axis] = 30.0 * u                     # any second channel, cut with the drive
    chans = {"tip_position": Channel("tip_position", t, pos, np.isfinite(pos), np.full(3, noise), "test"),
             "tip_force": Channel("tip_force", t, force, np.isfinite(force), np.full(3, 1e-3), "test")}
    if points:
        tf = t[::50]
        pts = np.zeros((2, tf.size, 3))
        pts[:, :, 0] = np.interp(tf, t, u)[None, :] * np.array([[0.5], [0.25]])
        chans["points"] = Channel("points", tf, pts, None, np.full(3, 1e-5), "test",
                                  reference=np.zeros((2, 3)), reference_frame=0)
    return Observations({name: ProtocolObservations(Protocol(name), chans, True)}, None, "synthetic")


CYCLES = [(4.0, 6.0, 0.0, 5.0), (4.0, 3.0, 0.05, 0.0), (5.0, 8.0, 0.2, 0.0), (4.0, 4.0, 0.0, 6.0)]


def check_cover(obs: Observations, segs: Observations) -> None:
    """Every sample of every channel in exactly one segment, in order, at its original time."""
    (po,) = list(obs)
    for cname, ch in po.channels.items():
        times = [s.channels[cname].time_s + s.protocol.parameters["segment_start_s"] for s in segs]
        assert np.allclose(np.concatenate(times), ch.time_s, atol=1e-9)
        axis = 1 if ch.is_points else 0
        vals = np.concatenate([s.channels[cname].values for s in segs], axis=axis)
        assert np.array_equal(np.isnan(vals), np.isnan(ch.values))
        assert np.allclose(np.nan_to_num(vals), np.nan_to_num(ch.values))


def test_cycles_of_a_synthetic_record_are_cut_in_their_rests() -> None:
    t, u, rests = programme(CYCLES)
    obs = session(t, u, points=True)
    segs = split(obs, "cycles")
    assert segs.names == [f"pull-cycle-{k}" for k in range(1, 5)]
    check_cover(obs, segs)
    starts = [s.protocol.parameters["segment_start_s"] for s in segs]
    for (r0, r1), cut in zip(rests[:-1], starts[1:], strict=True):
        # the middle of the dwell (within a sample and the 2 %-of-range tolerance of reaching it:
        # 2 % of 8 mm at 2 mm/s is 0.08 s), or the turning point itself
        assert abs(cut - 0.5 * (r0 + r1)) <= 0.08 + DT
    for s in segs:
        # re-zeroed, one hold at full amplitude each, noise and held-out mark kept
        assert s.channels["tip_position"].time_s[0] == pytest.approx(0.0, abs=1e-9)
        assert s.protocol.parameters["segment_of"] == "pull"
        assert np.nanmax(s.channels["tip_position"].values[:, 0]) == pytest.approx(AMP)
        assert s.held_out
        assert np.array_equal(s.channels["tip_force"].noise, obs["pull"].channels["tip_force"].noise)
    # the measured reference frame stays the reference only in the segment that holds it
    assert segs["pull-cycle-1"].channels["points"].reference_frame == 0
    assert all(segs[n].channels["points"].reference_frame is None for n in segs.names[1:])


def test_noise_and_spikes_on_the_drive_do_not_make_cycles() -> None:
    t, u, rests = programme(CYCLES)
    rng = np.random.default_rng(3)
    sigma = 0.03 * AMP                           # 3 % of the range: a third of the hysteresis margin / 2.2
    noisy = u + sigma * rng.standard_normal(u.size)
    spikes = rng.choice(u.size, 12, replace=False)
    noisy[spikes] += rng.choice([-1, 1], 12) * 0.8 * AMP    # isolated single-sample spikes
    segs = split(session(t, noisy, noise=sigma), "cycles")
    assert len(segs) == 4
    starts = [s.protocol.parameters["segment_start_s"] for s in segs]
    for (r0, r1), cut in zip(rests[:-1], starts[1:], strict=True):
        # the rest tolerance is 3 sigma = 9 % of the range here: 0.36 s of ramp either side
        assert r0 - 0.4 <= cut <= r1 + 0.4


def test_the_drive_is_the_component_with_the_largest_range_and_either_sign() -> None:
    t, u, _ = programme(CYCLES[:2])
    obs = session(t, -u, axis=2)                  # into the skin: negative z in the skin frame
    ch = obs["pull"].channels["tip_position"]
    ch.values[:, 0] = 1e-4 * np.sin(t)            # a smaller motion along x is not the drive
    ch.valid[:, 0] = True
    assert split(obs, "cycles").names == ["pull-cycle-1", "pull-cycle-2"]


@pytest.mark.parametrize("drive, message", [
    (lambda t: 0 * t, "does not move"),
    (lambda t: np.interp(t, [0, 2, 4, 10], [0, 0, AMP, AMP]), "does not return"),
    (lambda t: np.interp(t, [0, 2, 4, 6, 8, 10], [0.45 * AMP, 0.45 * AMP, AMP, AMP, 0, 0]), "starts loaded"),
    (lambda t: np.interp(t, [0, 4, 6, 10], [AMP, AMP, 0, 0]), "does not return towards rest"),
])
def test_records_without_cycles_are_clear_errors(drive, message) -> None:
    t = np.arange(0, 10, DT)
    with pytest.raises(SchemaError, match=message):
        split(session(t, drive(t)), "cycles")


def test_bad_requests_are_clear_errors() -> None:
    t, u, _ = programme(CYCLES[:1])
    obs = session(t, u)
    with pytest.raises(SchemaError, match="unknown segmentation 'halves'"):
        split(obs, "halves")
    po = obs["pull"]
    no_pos = Observations({"pull": ProtocolObservations(po.protocol,
                                                        {"tip_force": po.channels["tip_force"]})})
    with pytest.raises(SchemaError, match="no tip_position channel"):
        split(no_pos, "cycles")
    with pytest.raises(SchemaError, match="does not move"):
        cycle_cuts(t, 1e-7 * u / AMP, 1e-7)


needs_record = pytest.mark.skipif(not CSV.is_file(), reason="shared real data not beside the checkout")


@needs_record
def test_the_real_record_has_four_cycles_covering_it() -> None:
    whole = read_observations(CSV, axis="x")
    segs = read_observations(CSV, ["healthy_skin_extension_relaxation-cycle-3",
                                   "healthy_skin_extension_relaxation-cycle-4"], axis="x", segments="cycles")
    assert segs.names == [f"healthy_skin_extension_relaxation-cycle-{k}" for k in range(1, 5)]
    assert [s.held_out for s in segs] == [False, False, True, True]
    check_cover(whole, segs)
    top = 9.45e-3
    for s in segs:
        x = s.channels["tip_position"].values[:, 0]
        # each segment holds one ramp to 9.45 mm (resolution 0.01 mm) and starts below 20 % of it
        # (the README: the third return stops near 1.8 mm)
        assert abs(x.max() - top) <= 2e-5
        assert x[0] < 0.2 * top
        held = s.channels["tip_position"].time_s[x > top - 5e-5]
        assert held[-1] - held[0] > 30.0                     # holds of 45-60 s (README), at least 30
        assert np.all(np.diff(held) < 1.0)                    # one hold per segment, not two


@needs_record
def test_a_memoryless_model_predicts_the_same_on_segments_as_on_the_whole_record() -> None:
    # the hyperelastic element has no history: cutting the record must not change its prediction
    model = load(ROOT / "docs" / "models" / "extension_relaxation_lumped.toml")
    whole = read_observations(CSV, axis="x")
    segs = split(whole, "cycles")
    pw = model.predict(model.parameters(), whole).protocols[whole.names[0]]["tip_force"].values
    ps = np.concatenate([model.predict(model.parameters(), segs).protocols[n]["tip_force"].values
                         for n in segs.names])
    assert np.allclose(ps, pw, rtol=0, atol=1e-12)
