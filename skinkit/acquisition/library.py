"""The thesis's measurement protocols as named, parameterised :class:`~skinkit.schemas.Protocol` objects.

Sources (reference text):

* ``preconditioning`` -- 7.2.1: after contact, a 2 mm normal indentation held 30 s while the
  adhesive sets and the skin preconditions, then back to zero.
* ``normal_indentation``, ``in_plane_000`` ... ``in_plane_330`` (12 directions, 30 deg apart),
  ``normal_retraction``, ``out_of_plane_330/285/240`` (45 deg from the skin plane) -- 7.2.1 and
  Table 12: 1.5 mm peak-to-peak sinusoid at 0.1 Hz for three periods. The sinusoid is
  one-sided, ``pp/2 (1 - cos 2 pi f t)``, so each direction is a stretch from the zero
  position and back (retraction is the normal direction pulled out of the skin). ``rest``
  (default 0 s) holds the zero position first: a reader estimates the sensors' noise and its
  colour from those samples (at least 200 for an autoregressive model).
* ``stochastic_preconditioning`` -- 4.1.3: 0.5 Hz sinusoidal ramp from zero to full force for
  three periods, 10 s at full force, then 100 s of the stochastic input.
* ``stochastic_full_scale`` -- 4.1.3: Gaussian force, low-passed at 200 Hz, up to 3.5 N per
  motor, all three motors together (normal) or one motor with the others held (tangential).
* ``incremental_a`` / ``incremental_b`` -- 4.1.3: the stochastic input scaled to 20 % with its
  mean stepped across the full range, 15 increments then 15 decrements; A precedes each
  step with a zero-max-zero force triangle, B holds the step's mean.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from skinkit.acquisition.programmes import Programme, direction, one_sided_sine, stochastic
from skinkit.errors import SkinkitError
from skinkit.schemas import Protocol


class ProtocolError(SkinkitError):
    """An unknown protocol name or a bad protocol parameter."""


@dataclass(frozen=True)
class _Entry:
    kind: str
    description: str
    defaults: dict[str, Any]
    units: dict[str, str]
    build: Callable[[dict[str, Any]], Programme]
    #: number of setpoints ``build`` makes, without making them (listing stays cheap: the
    #: stochastic programmes would import scipy.signal and filter 10^5 samples each)
    length: Callable[[dict[str, Any]], int]


def _n(seconds: Any, p: dict[str, Any]) -> int:
    """Setpoints in ``seconds`` at the programme's rate (the builders' own rounding)."""
    return int(round(float(seconds) * float(p["setpoint_rate"])))


def _sine_length(p: dict[str, Any]) -> int:
    return _n(float(p.get("rest", 0.0)), p) + _n(float(p["periods"]) / float(p["frequency"]), p) + 1


def _precondition_length(p: dict[str, Any]) -> int:
    return _n(2 * float(p["ramp"]) + float(p["hold"]), p) + 1


def _full_scale_length(p: dict[str, Any]) -> int:
    return _n(p["duration"], p) + 1


def _stoch_precondition_length(p: dict[str, Any]) -> int:
    return _n(3 / 0.5, p) + _n(p["hold"], p) + _n(p["duration"], p) + 1


def _incremental_length(p: dict[str, Any]) -> int:
    return 2 * int(p["increments"]) * (_n(p["increment_duration"], p)
                                       + _n(p["precondition_duration"], p)) + 1


_SINE_UNITS = {
    "theta": "deg",
    "phi": "deg",
    "peak_to_peak": "m",
    "frequency": "Hz",
    "periods": "1",
    "rest": "s",
    "setpoint_rate": "Hz",
    "camera_rate": "Hz",
}


def _sine(p: dict[str, Any]) -> Programme:
    rate = float(p["setpoint_rate"])
    rest = float(p.get("rest", 0.0))
    if not rest >= 0:
        raise ProtocolError(f"parameter 'rest' must be >= 0 s, got {rest}")
    duration = float(p["periods"]) / float(p["frequency"])
    t = np.arange(int(round(duration * rate)) + 1) / rate
    # a rest at zero first: the samples a reader estimates the sensors' noise and its colour from
    s = np.concatenate([np.zeros(_n(rest, p)), one_sided_sine(t, float(p["peak_to_peak"]),
                                                               float(p["frequency"]))])
    return Programme(
        "trajectory",
        rate,
        s[:, None] * direction(float(p["theta"]), float(p["phi"])),
        float(p["camera_rate"]),
    )


def _precondition(p: dict[str, Any]) -> Programme:
    rate = float(p["setpoint_rate"])
    ramp, hold, depth = float(p["ramp"]), float(p["hold"]), float(p["depth"])
    t = np.arange(int(round((2 * ramp + hold) * rate)) + 1) / rate
    # smooth (raised-cosine) ramps so the PID is not asked for a velocity step
    up = 0.5 * (1 - np.cos(np.pi * np.clip(t / ramp, 0, 1)))
    down = 0.5 * (1 - np.cos(np.pi * np.clip((t - ramp - hold) / ramp, 0, 1)))
    z = depth * (up - down)
    return Programme("trajectory", rate, np.stack([0 * z, 0 * z, z], axis=1), float(p["camera_rate"]))


def _motor_columns(f: np.ndarray, p: dict[str, Any]) -> np.ndarray:
    """Per-motor forces: all motors (``axis`` 0, normal) or one motor with the others held."""
    axis = int(p["axis"])
    if axis not in (0, 1, 2, 3):
        raise ProtocolError(f"parameter 'axis' must be 0 (normal, all motors) or a motor 1..3, got {axis}")
    if axis == 0:
        return np.repeat(f[:, None], 3, axis=1)
    out = np.full((f.size, 3), float(p["hold_force"]))
    out[:, axis - 1] = f
    return out


_FORCE_UNITS = {
    "force_max": "N",
    "duration": "s",
    "cutoff": "Hz",
    "setpoint_rate": "Hz",
    "axis": "1",
    "hold_force": "N",
    "seed": "1",
    "camera_rate": "Hz",
}


def _full_scale(p: dict[str, Any]) -> Programme:
    rate = float(p["setpoint_rate"])
    n = int(round(float(p["duration"]) * rate)) + 1
    u = stochastic(n, rate, float(p["cutoff"]), int(p["seed"]))
    f = float(p["force_max"]) * (0.5 + u / 6.0)  # +-3 sigma spans 0..force_max
    return Programme("force", rate, _motor_columns(f, p), float(p["camera_rate"]))


def _stoch_precondition(p: dict[str, Any]) -> Programme:
    rate, fmax = float(p["setpoint_rate"]), float(p["force_max"])
    f_ramp = 0.5
    t1 = np.arange(int(round(3 / f_ramp * rate))) / rate
    ramp = fmax * 0.5 * (1 - np.cos(2 * np.pi * f_ramp * t1)) * np.clip(t1 * f_ramp / 3 * 2, 0, 1)
    hold = np.full(int(round(float(p["hold"]) * rate)), fmax)
    n = int(round(float(p["duration"]) * rate)) + 1
    u = stochastic(n, rate, float(p["cutoff"]), int(p["seed"]))
    f = np.concatenate([ramp, hold, fmax * (0.5 + u / 6.0)])
    return Programme("force", rate, _motor_columns(f, p), float(p["camera_rate"]))


def _incremental(variant: str) -> Callable[[dict[str, Any]], Programme]:
    def build(p: dict[str, Any]) -> Programme:
        rate, fmax = float(p["setpoint_rate"]), float(p["force_max"])
        k, scale = int(p["increments"]), float(p["scale"])
        n_inc = int(round(float(p["increment_duration"]) * rate))
        n_pre = int(round(float(p["precondition_duration"]) * rate))
        means = np.linspace(scale / 2, 1 - scale / 2, k)
        means = np.concatenate([means, means[::-1]])
        u = stochastic(n_inc * means.size + 1, rate, float(p["cutoff"]), int(p["seed"]))
        parts = []
        for j, m in enumerate(means):
            if variant == "a":  # zero - max - zero triangle
                pre = fmax * (1 - np.abs(np.linspace(-1, 1, n_pre)))
            else:  # hold the step's mean
                pre = np.full(n_pre, fmax * m)
            parts += [pre, fmax * (m + scale * u[j * n_inc : (j + 1) * n_inc] / 6.0)]
        parts.append(np.array([fmax * means[-1]]))
        return Programme("force", rate, _motor_columns(np.concatenate(parts), p), float(p["camera_rate"]))

    return build


def _trajectory_entries() -> dict[str, _Entry]:
    """The position-controlled protocols: preconditioning and the sinusoids of Table 12."""
    sine = {
        "peak_to_peak": 1.5e-3,
        "frequency": 0.1,
        "periods": 3,
        "rest": 0.0,
        "setpoint_rate": 100.0,
        "camera_rate": 1.0,
    }
    out: dict[str, _Entry] = {
        "preconditioning": _Entry(
            "trajectory",
            "2 mm normal indentation held 30 s after contact (thesis 7.2.1)",
            {"depth": 2e-3, "hold": 30.0, "ramp": 1.0, "setpoint_rate": 100.0, "camera_rate": 0.0},
            {"depth": "m", "hold": "s", "ramp": "s", "setpoint_rate": "Hz", "camera_rate": "Hz"},
            _precondition,
            _precondition_length,
        ),
        "normal_indentation": _Entry(
            "trajectory",
            "1.5 mm p-p sinusoid into the skin, 0.1 Hz, 3 periods (Table 12)",
            {"theta": 0.0, "phi": 90.0, **sine},
            _SINE_UNITS,
            _sine,
            _sine_length,
        ),
    }
    for theta in range(0, 360, 30):
        out[f"in_plane_{theta:03d}"] = _Entry(
            "trajectory",
            f"1.5 mm p-p in-plane stretch at theta={theta} deg (Table 12)",
            {"theta": float(theta), "phi": 0.0, **sine},
            _SINE_UNITS,
            _sine,
            _sine_length,
        )
    out["normal_retraction"] = _Entry(
        "trajectory",
        "1.5 mm p-p sinusoid pulling the skin out along the normal (Table 12)",
        {"theta": 0.0, "phi": -90.0, **sine},
        _SINE_UNITS,
        _sine,
        _sine_length,
    )
    for theta in (330, 285, 240):
        out[f"out_of_plane_{theta:03d}"] = _Entry(
            "trajectory",
            f"1.5 mm p-p at 45 deg out of plane, theta={theta} deg (Table 12)",
            {"theta": float(theta), "phi": 45.0, **sine},
            _SINE_UNITS,
            _sine,
            _sine_length,
        )
    return out


def _force_entries() -> dict[str, _Entry]:
    """The force-controlled protocols: stochastic inputs of thesis 4.1.3 and Protocols A and B."""
    out: dict[str, _Entry] = {}
    force = {
        "force_max": 3.5,
        "cutoff": 200.0,
        "setpoint_rate": 1000.0,
        "axis": 0,
        "hold_force": 1.0,
        "seed": 0,
        "camera_rate": 0.0,
    }
    out["stochastic_preconditioning"] = _Entry(
        "force",
        "0.5 Hz ramp to full force x3, 10 s hold, 100 s stochastic (thesis 4.1.3)",
        {**force, "hold": 10.0, "duration": 100.0},
        {**_FORCE_UNITS, "hold": "s"},
        _stoch_precondition,
        _stoch_precondition_length,
    )
    out["stochastic_full_scale"] = _Entry(
        "force",
        "Gaussian force 0..3.5 N per motor, low-passed at 200 Hz, 100 s (thesis 4.1.3)",
        {**force, "duration": 100.0},
        _FORCE_UNITS,
        _full_scale,
        _full_scale_length,
    )
    inc = {**force, "increments": 15, "scale": 0.2, "increment_duration": 10.0, "precondition_duration": 2.0}
    inc_units = {
        **_FORCE_UNITS,
        "increments": "1",
        "scale": "1",
        "increment_duration": "s",
        "precondition_duration": "s",
    }
    inc_units.pop("duration")
    out["incremental_a"] = _Entry(
        "force",
        "20 % stochastic input stepped up then down 15x, triangle preconditioning (Protocol A)",
        inc,
        inc_units,
        _incremental("a"),
        _incremental_length,
    )
    out["incremental_b"] = _Entry(
        "force",
        "20 % stochastic input stepped up then down 15x, mean-hold preconditioning (Protocol B)",
        inc,
        inc_units,
        _incremental("b"),
        _incremental_length,
    )
    return out


def _catalogue() -> dict[str, _Entry]:
    """Every built-in protocol, in thesis order."""
    return {**_trajectory_entries(), **_force_entries()}


_CATALOGUE = _catalogue()


def names() -> list[str]:
    """Names of the built-in protocols, in thesis order."""
    return list(_CATALOGUE)


def _resolve(name: str, parameters: dict[str, Any]) -> tuple[_Entry, dict[str, Any]]:
    """The catalogue entry of ``name`` and its defaults overridden by ``parameters``."""
    entry = _CATALOGUE.get(name)
    if entry is None:
        raise ProtocolError(f"unknown protocol {name!r}; known: {', '.join(_CATALOGUE)}")
    unknown = sorted(set(parameters) - set(entry.defaults))
    if unknown:
        raise ProtocolError(
            f"protocol {name!r} has no parameter(s) {unknown}; parameters: {sorted(entry.defaults)}"
        )
    params = dict(entry.defaults)
    for key, value in parameters.items():
        kind = type(entry.defaults[key])
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ProtocolError(
                f"protocol {name!r}: parameter {key!r} must be a number, got {value!r}"
            ) from None
        # a count (periods, increments, seed) cut to a whole number would run another protocol
        # than the one asked for: 1.5 periods is not 1
        if kind is int and not (math.isfinite(number) and number.is_integer()):
            raise ProtocolError(
                f"protocol {name!r}: parameter {key!r} must be a whole number, got {value!r}"
            )
        params[key] = int(number) if kind is int else kind(value)
    return entry, params


def make_protocol(name: str, **parameters: Any) -> Protocol:
    """The protocol ``name`` with its defaults overridden by ``parameters`` (in the units
    :func:`describe` lists). Raises :class:`ProtocolError` naming an unknown protocol or parameter,
    or parameters its programme cannot be built from (the programme is built to check)."""
    entry, params = _resolve(name, parameters)
    proto = Protocol(
        name, kind=entry.kind, parameters=params, units=dict(entry.units), description=entry.description
    )
    prog = programme(proto)
    return Protocol(
        name,
        kind=entry.kind,
        parameters=params,
        units=dict(entry.units),
        duration_s=prog.duration_s,
        description=entry.description,
    )


#: most setpoints a programme may have (10^7: about 28 h at 100 Hz, 0.2 GB of setpoints)
MAX_SETPOINTS = 10_000_000


def programme(protocol: Protocol) -> Programme:
    """The setpoints of ``protocol`` (a built-in name with any parameter values)."""
    entry = _CATALOGUE.get(protocol.name)
    if entry is None:
        raise ProtocolError(f"no programme for protocol {protocol.name!r}; known: {', '.join(_CATALOGUE)}")
    params = {**entry.defaults, **protocol.parameters}
    for key in ("setpoint_rate", "frequency", "periods"):
        if key in params and not float(params[key]) > 0:
            raise ProtocolError(
                f"protocol {protocol.name!r}: parameter {key!r} must be > 0, got {params[key]}"
            )
    for key, value in params.items():
        if isinstance(value, float) and not math.isfinite(value):
            raise ProtocolError(f"protocol {protocol.name!r}: parameter {key!r} must be finite, got {value}")
    try:
        n = entry.length(params)
    except (ValueError, ZeroDivisionError, OverflowError) as exc:
        raise ProtocolError(f"protocol {protocol.name!r}: cannot build its programme ({exc})") from None
    if n > MAX_SETPOINTS:  # refuse from the count, before allocating the setpoints
        raise ProtocolError(
            f"protocol {protocol.name!r}: {n:,} setpoints (duration x setpoint_rate), over the "
            f"limit of {MAX_SETPOINTS:,}; lower setpoint_rate or shorten the protocol"
        )
    try:
        return entry.build(params)
    except (ValueError, ZeroDivisionError) as exc:
        raise ProtocolError(f"protocol {protocol.name!r}: cannot build its programme ({exc})") from None


def catalogue() -> list[Protocol]:
    """Every built-in protocol with its default parameters and planned duration [s].

    The durations come from each programme's length rule, not from building the
    programmes (the defaults are valid, so nothing is left unchecked), which keeps
    ``skinkit robot protocols`` fast."""
    out = []
    for name, entry in _CATALOGUE.items():
        params = dict(entry.defaults)
        out.append(Protocol(name, kind=entry.kind, parameters=params, units=dict(entry.units),
                            duration_s=(entry.length(params) - 1) / float(params["setpoint_rate"]),
                            description=entry.description))
    return out
