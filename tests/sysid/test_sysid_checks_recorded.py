"""``check_signals`` gives, bit for bit, the outputs recorded before it was split into named
steps: every branch (gaps, jitter, short and long NaN runs, clipping,
saturation flags, a narrowband input, a short record, each refusal) on seeded inputs.

A pure refactor must not change one bit, so the check is exact: the signals' SHA-256, the
sampling, the start time and every warning and error message. To record again after an
intended change of behaviour: ``python tests/sysid/test_sysid_checks_recorded.py --record``.
"""

from __future__ import annotations

import hashlib
import json
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from skinkit.schemas.robot import FLAG_SATURATED
from skinkit.sysid.checks import SysidError, check_signals

RECORDED = Path(__file__).with_name("check_signals_recorded.json")
N = 4000
RATE = 1000.0


#: the response's pole, e^(-1/8), as a literal (a libm's last bit is not the same everywhere)
POLE = 0.8824969025845955


def _base(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A seeded force and a first-order response to it. The response is a recursion in Python
    floats, each step one IEEE rounding, so its bits do not depend on the numpy release: the
    first recording used ``np.convolve``, whose bits changed in a later numpy (2.4.6 gave other
    position digests while every other output still matched), and was recorded again on this
    input (2026-11-24)."""
    rng = np.random.default_rng(seed)
    f = rng.standard_normal(N)
    y = np.empty(N)
    acc = 0.0
    for i, x in enumerate(f.tolist()):
        acc = POLE * acc + x
        y[i] = acc
    return f, y * 1e-4 + 1e-6 * rng.standard_normal(N)


def _cases() -> dict[str, tuple[tuple, dict[str, Any]]]:
    """name -> (args, kwargs) of one call."""
    f, y = _base(0)
    t = np.arange(N) / RATE
    out: dict[str, tuple[tuple, dict[str, Any]]] = {}
    out["uniform"] = ((f, y), {"rate_hz": RATE, "memory_s": 0.05})
    tg = t.copy()
    tg[1500:] += 0.2
    tg[3200:] += 0.05
    out["gaps"] = ((f, y), {"time_s": tg})
    tj = t + np.random.default_rng(1).uniform(-0.2, 0.2, N) / RATE
    out["jitter"] = ((f, y), {"time_s": tj})
    fn = f.copy()
    fn[[100, 101, 700, 2500]] = np.nan
    yn = y.copy()
    yn[1200:1210] = np.nan
    out["nan_short_and_long"] = ((fn, yn), {"rate_hz": RATE})
    out["nan_jitter_gap"] = ((fn, yn), {"time_s": np.where(np.arange(N) >= 3000, tj + 0.3, tj)})
    fe = f.copy()
    fe[0] = np.nan          # runs at the edges are cut, not interpolated
    fe[-2:] = np.nan
    out["nan_at_edges"] = ((fe, y), {"rate_hz": RATE})
    fc = np.clip(f, -1.5, 1.5)
    flags = np.zeros(N, np.uint32)
    flags[::50] = FLAG_SATURATED
    out["clipped_flags_limit"] = ((fc, np.clip(y, -2e-4, 2e-4)),
                                  {"rate_hz": RATE, "force_limit_N": 1.5, "flags": flags})
    ramp = np.concatenate([np.linspace(0, 1, N // 2), np.ones(N - N // 2)])
    out["narrowband"] = ((ramp + 1e-3 * f, 1e-3 * ramp + 1e-6 * y), {"rate_hz": RATE})
    out["short_record"] = ((f[:700], y[:700]), {"rate_hz": RATE, "memory_s": 0.1})
    out["lists_not_arrays"] = ((list(f[:300]), list(y[:300])), {"rate_hz": RATE})
    # refusals
    out["err_sizes"] = ((f, y[:-1]), {"rate_hz": RATE})
    out["err_too_few"] = ((f[:10], y[:10]), {"rate_hz": RATE})
    out["err_both_rate_and_time"] = ((f, y), {"rate_hz": RATE, "time_s": t})
    out["err_neither"] = ((f, y), {})
    out["err_flags_shape"] = ((f, y), {"rate_hz": RATE, "flags": flags[:-1]})
    out["err_2d"] = ((np.stack([f, f]), y), {"rate_hz": RATE})
    out["err_inf"] = ((np.where(np.arange(N) == 9, np.inf, f), y), {"rate_hz": RATE})
    out["err_text"] = (("abc", y), {"rate_hz": RATE})
    out["err_time_not_increasing"] = ((f, y), {"time_s": np.where(np.arange(N) == 5, t[3], t)})
    out["err_time_nan"] = ((f, y), {"time_s": np.where(np.arange(N) == 7, np.nan, t)})
    out["err_time_size"] = ((f, y), {"time_s": t[:-1]})
    out["err_gap_leaves_too_few"] = ((f, y), {"time_s": t + 1.0 * (np.arange(N) // 40)})
    fl = f.copy()
    fl[50::60] = np.nan
    fl[51::60] = np.nan
    fl[52::60] = np.nan
    out["err_nan_leaves_too_few"] = ((fl, y), {"rate_hz": RATE})
    out["err_rate"] = ((f, y), {"rate_hz": -5.0})
    out["err_rate_nan"] = ((f, y), {"rate_hz": float("nan")})
    out["err_constant_force"] = ((np.ones(N), y), {"rate_hz": RATE})
    out["err_constant_position"] = ((f, np.zeros(N)), {"rate_hz": RATE})
    out["err_memory"] = ((f, y), {"rate_hz": RATE, "memory_s": -1.0})
    out["err_memory_too_long"] = ((f, y), {"rate_hz": RATE, "memory_s": 1.0})
    return out


def _digest(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a, dtype=np.float64).tobytes()).hexdigest()


def _run(args: tuple, kwargs: dict[str, Any]) -> dict[str, Any]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            s = check_signals(*args, **kwargs)
        except SysidError as exc:
            return {"error": str(exc)}
    return {"n": s.n, "rate_hz": s.rate_hz.hex(), "t0_s": s.t0_s.hex(),
            "force_N": _digest(s.force_N), "position_m": _digest(s.position_m),
            "force_first": s.force_N[:3].tolist(), "issues": s.issues,
            "warnings": [f"{w.category.__name__}: {w.message}" for w in caught]}


def _record() -> dict[str, Any]:
    return {name: _run(*call) for name, call in _cases().items()}


@pytest.mark.parametrize("name", sorted(_cases()))
def test_check_signals_matches_its_recorded_output(name):
    recorded = json.loads(RECORDED.read_text())
    assert set(recorded) == set(_cases())
    assert _run(*_cases()[name]) == recorded[name]


if __name__ == "__main__":
    if "--record" in sys.argv:
        RECORDED.write_text(json.dumps(_record(), indent=1, sort_keys=True) + "\n")
        print(f"recorded {RECORDED}")
