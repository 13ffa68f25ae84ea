"""``[[instrument]]`` entries: linear transforms between what the skin saw and what was recorded.

Each entry has one main parameter (``parameter``, value ``value``; 0 is no effect, exactly),
linear in it but for a lag's shift in time, and applies to one channel (``docs/guide/effects.md``):

* ``bias``: recorded = true + value · b(t) on ``component`` of ``channel``, b = 1
  (``basis = "constant"``), t [s] (``"time"``), 1 − exp(−t/τ) (``"warmup"``: a sensor's
  zero settling to ``value`` with time constant ``tau`` [s] > 0, a second parameter when
  ``tau_parameter`` names it) or B(t/τ − k) − B(−k) (``"spline"``: the uniform cubic
  B-spline centred on knot ``knot`` = k ≥ 1 of a grid with spacing ``tau`` [s] > 0 from the
  record's start; a sum of them is a smooth wander through 0 at t = 0 with no feature
  faster than about 2τ). On the channel that drives a model the model is driven by
  recorded − value · b(t). t is the channel's sample time, counted from its protocol's
  start (``Channel.time_s``): a time basis restarts at 0 with every protocol, as for a
  sensor zeroed at the start of each record.
* ``series``: recorded ``channel`` = true + value · ``source`` channel (a compliance [m/N]
  between the motor and the tip: ``channel = "tip_position"``, ``source = "tip_force"``).
* ``similarity``: recorded points = (1 + value) p (``mode = "scale"``) or p turned by
  ``value`` [rad] about the normal through the origin (``mode = "rotation"``), for
  ``points`` and ``points_2d``.
* ``tilt``: the robot's frame is turned by ``value`` [rad] about the in-plane axis at
  ``azimuth`` [rad] from x relative to the skin's (the probe's axis misaligned): the drive
  it records acts along turned directions on the skin, and the tip channels it records
  are the skin-frame ones turned back (points, seen by the cameras, are not). ``azimuth``
  is a second parameter when ``azimuth_parameter`` names it.
* ``friction``: recorded = true + value · tanh(v(t)/``velocity``) on ``component`` of ``channel``
  (``tip_force``), v [m/s] the velocity of the same component of the ``source`` channel
  (``tip_position``), estimated by a Savitzky–Golay derivative (local quadratic) over
  ``window`` [s] (default 0.1 s) so that the position sensor's noise does not flip the sign at
  rest; ``velocity`` [m/s] (default 0.1 mm/s) smooths the sign. A rate-independent friction
  (Coulomb's law, regularised) read by the force sensor; linear in ``value``. The source's own
  derivatives are carried through (∂/∂θ = value · sech²(v/v_s) ∂v/∂θ / v_s). Refused on the
  driving channel (the drive would depend on the prediction, as for a series entry).
* ``lag``: the ``channel`` (``tip_force``, the default, or ``tip_position``) is sampled
  ``value`` [s] late relative to the others (two acquisition chains whose clocks are skewed):
  recorded(t) = c(t − value), c what the channel's chain put out (the true channel with the
  channel's other entries). |value| ≤ ``MAX_LAG_S``. c between samples is the not-a-knot
  cubic spline through the channel's samples (exact for cubics; error ≤ ~(5/384) h⁴ max|c⁗|
  for a sampling step h); before the first sample c is the first sample's value and after
  the last the last's (the record starts and ends at rest). ∂/∂value = −c′(t − value), the
  spline's own derivative (so it is the exact derivative of the transform, not an estimate),
  0 where t − value lies outside the record. Tracked points are never shifted. On the
  driving channel the model is driven by the recorded channel read ``value`` earlier.

API (model-agnostic; arrays in, arrays and derivative dicts out; shapes: tip channels
``(T, 3)``, points ``(P, T, 3)``, 2D points ``(P, T, 2)``, times ``(T,)`` [s]):

* ``parse(entries) -> list[Entry]`` validates the tables (errors name ``instrument[i].<key>``;
  ``value`` and ``azimuth`` are numbers in SI or ``"<number> <unit>"`` strings);
* ``parameter_names(entries) -> list[str]`` and ``parameter_unit(entry) -> str``;
* ``drive(entries, channel, time_s, recorded, names) -> (true, {name: d true/d name})``: the
  recorded drive ``(T, 3)`` to what the skin saw (lags of that channel undone, its biases
  removed, then the tilt). A series entry on the driving channel is refused here: it couples the drive to the
  prediction, so the model itself must solve it (the lumped model does);
* ``unrecord_points(entries, channel, recorded, shift) -> (P, k)``: the material reference
  positions of tracked points whose reference was itself recorded (a measured reference frame:
  the tracker's calibration error applies to it too), the similarity entries undone;
* ``measure(entries, channel, time_s, values, d, channels, names) -> (recorded, derivatives)``:
  a predicted channel (skin frame) with the model's derivatives ``d`` to what the instrument
  records, the model's derivatives carried through and the instrument's own added for
  ``names``; ``channels`` maps every channel the model knows (predicted or driving) to
  ``(values, derivatives)`` for the ``source`` of series entries (chain rule included);
* ``with_values(entries, values) -> list[Entry]``: the entries with the parameters named in
  ``values`` set (``value``, ``azimuth``, ``tau``);
* ``shift(time_s, y, delay) -> (y(t − delay), y′(t − delay))``: the lag's interpolation.

Every transform is exactly the identity at value 0 (a tilt: at angle 0, any azimuth; a
warm-up: at any ``tau``).

Order: on a measured channel the ``bias``, ``series``, ``similarity`` and ``tilt`` entries
apply in the order given, then the channel's ``lag`` entries (the acquisition reads the whole
chain late); on the driving channel the inverse: lags undone, biases removed, tilt.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_filter

from skinkit.errors import ForwardError
from skinkit.schemas import Parameter

KINDS = ("bias", "series", "similarity", "tilt", "lag", "friction")
_CHANNELS = ("tip_force", "tip_position", "points", "points_2d")
_TIP = ("tip_force", "tip_position")
_POINTS = ("points", "points_2d")
_BASES = ("constant", "time", "warmup", "spline")
#: bases with a time scale ``tau`` [s]
_SCALED = ("warmup", "spline")
#: a friction's default sign-smoothing velocity [m/s] and velocity-estimate window [s]
FRICTION_VELOCITY_M_S = 1e-4
FRICTION_WINDOW_S = 0.1
#: largest |lag| [s]: a skew between acquisition chains is milliseconds; half a second is a
#: misaligned record, not a lag
MAX_LAG_S = 0.5


@dataclass(frozen=True)
class Entry:
    """One validated ``[[instrument]]`` entry."""

    kind: str
    parameter: str
    value: float
    channel: str = ""
    component: int = 0
    basis: str = "constant"
    source: str = ""
    mode: str = ""
    azimuth: float = 0.0
    azimuth_parameter: str = ""
    tau: float = 0.0
    tau_parameter: str = ""
    knot: int = 0
    velocity: float = 0.0
    window: float = 0.0


def parse(entries: Any) -> list[Entry]:
    """Validate ``[[instrument]]`` tables (errors name ``instrument[i].<key>``)."""
    if entries is None:
        return []
    if not isinstance(entries, list):
        raise ForwardError("instrument", "must be an array of tables ([[instrument]])")
    return [_entry(f"instrument[{i}]", e) for i, e in enumerate(entries)]


_KEYS = {"kind", "parameter", "value", "channel", "component", "basis", "source", "mode", "azimuth",
         "azimuth_parameter", "tau", "tau_parameter", "knot", "velocity", "window"}


def _entry(w: str, e: Any) -> Entry:
    """One table as an :class:`Entry` (``w``: its name in errors, ``instrument[i]``)."""
    if not isinstance(e, Mapping):
        raise ForwardError(w, "must be a table")
    kind = e.get("kind")
    if kind not in KINDS:
        raise ForwardError(f"{w}.kind", f"must be one of {list(KINDS)}, got {kind!r}")
    extra = sorted(set(e) - _KEYS)
    if extra:
        raise ForwardError(w, f"unknown key(s) {extra}")
    par = str(e.get("parameter", ""))
    if not par:
        raise ForwardError(f"{w}.parameter", "needs a parameter name")
    ch = _channel(w, kind, e)
    comp = e.get("component", 0)
    if kind in ("bias", "friction") and comp not in (0, 1, 2):
        raise ForwardError(f"{w}.component", f"must be 0, 1 or 2, got {comp!r}")
    basis = str(e.get("basis", "constant"))
    if basis not in _BASES:
        raise ForwardError(f"{w}.basis", f"must be one of {list(_BASES)}, got {basis!r}")
    if "tau" in e and not (kind == "bias" and basis in _SCALED):
        raise ForwardError(f"{w}.tau",
                           "a time scale belongs to a bias with basis = 'warmup' or 'spline' only")
    if "tau_parameter" in e and not (kind == "bias" and basis == "warmup"):
        raise ForwardError(f"{w}.tau_parameter", "only a warm-up's time constant can be a parameter")
    knot = _knot(e, kind, basis, w)
    mode = str(e.get("mode", "scale" if kind == "similarity" else ""))
    if kind == "similarity" and mode not in ("scale", "rotation"):
        raise ForwardError(f"{w}.mode", f"must be 'scale' or 'rotation', got {mode!r}")
    src = str(e.get("source", {"series": "tip_force", "friction": "tip_position"}.get(kind, "")))
    if kind in ("series", "friction") and src not in _TIP:
        raise ForwardError(f"{w}.source", f"must be 'tip_force' or 'tip_position', got {src!r}")
    if kind == "friction" and src == ch:
        raise ForwardError(f"{w}.source", "a friction reads the velocity of another channel than the one "
                           f"it acts on, got {src!r} for both")
    entry = Entry(kind, par, 0.0, ch, int(comp), basis, src, mode, 0.0, str(e.get("azimuth_parameter", "")),
                  0.0, str(e.get("tau_parameter", "")))
    value = _number(e.get("value", 0.0), parameter_unit(entry), f"{w}.value")
    if kind == "lag" and not abs(value) <= MAX_LAG_S:
        raise ForwardError(f"{w}.value", f"a lag of {value:g} s is outside ±{MAX_LAG_S:g} s")
    az = _number(e.get("azimuth", 0.0), "rad", f"{w}.azimuth")
    vel, win = _friction_scales(e, kind, w)
    return replace(entry, value=value, azimuth=az, tau=_tau(e, basis, w), knot=knot, velocity=vel, window=win)


def _friction_scales(e: Mapping[str, Any], kind: str, where: str) -> tuple[float, float]:
    """A friction's sign-smoothing velocity [m/s] and velocity window [s] (both > 0); 0, 0 for
    the other kinds (which refuse the keys)."""
    if kind != "friction":
        for k in ("velocity", "window"):
            if k in e:
                raise ForwardError(f"{where}.{k}", "belongs to a friction entry only")
        return 0.0, 0.0
    vel = _number(e.get("velocity", FRICTION_VELOCITY_M_S), "m/s", f"{where}.velocity")
    win = _number(e.get("window", FRICTION_WINDOW_S), "s", f"{where}.window")
    for k, x, u in (("velocity", vel, "m/s"), ("window", win, "s")):
        if not x > 0:
            raise ForwardError(f"{where}.{k}", f"must be positive, got {x:g} {u}")
    return vel, win


def _channel(w: str, kind: str, e: Mapping[str, Any]) -> str:
    """The channel an entry acts on (``""`` for a tilt: both tip channels)."""
    if kind == "tilt":
        return ""
    ch = str(e.get("channel", {"series": "tip_position", "lag": "tip_force",
                               "friction": "tip_force"}.get(kind, "")))
    if kind == "friction" and ch not in _TIP:
        raise ForwardError(f"{w}.channel", f"a friction acts on a tip channel: must be one of "
                           f"{list(_TIP)}, got {ch!r}")
    if kind == "lag" and ch not in _TIP:
        raise ForwardError(f"{w}.channel", f"a lag shifts a tip channel in time: must be one of "
                           f"{list(_TIP)}, got {ch!r}")
    if ch not in _CHANNELS:
        raise ForwardError(f"{w}.channel", f"must be one of {list(_CHANNELS)}, got {ch!r}")
    return ch


def _tau(e: Mapping[str, Any], basis: str, where: str) -> float:
    """A warm-up's time constant or a spline's knot spacing [s] (> 0, required); 0 for the
    other bases."""
    if basis not in _SCALED:
        return 0.0
    what = "time constant" if basis == "warmup" else "knot spacing"
    if "tau" not in e:
        raise ForwardError(f"{where}.tau", f"a bias with basis = {basis!r} needs a {what} tau [s]")
    tau = _number(e["tau"], "s", f"{where}.tau")
    if not tau > 0:
        raise ForwardError(f"{where}.tau", f"a {what} must be positive, got {tau:g} s")
    return tau


def _knot(e: Mapping[str, Any], kind: str, basis: str, where: str) -> int:
    """A spline basis's knot (a whole number >= 1, required); 0 for the other bases."""
    if basis != "spline" or kind != "bias":
        if "knot" in e:
            raise ForwardError(f"{where}.knot", "a knot belongs to a bias with basis = 'spline' only")
        return 0
    k = e.get("knot")
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ForwardError(f"{where}.knot", f"must be a whole number >= 1 (the knot the B-spline is "
                           f"centred on, counted from the record's start), got {k!r}")
    return int(k)


def _number(value: Any, unit: str, where: str) -> float:
    """A finite SI value from a number or a ``"<number> <unit>"`` string (``"-77 mN"``, ``"3 deg"``)."""
    if isinstance(value, str):
        from skinkit.fem.errors import ModelError
        from skinkit.fem.model import quantity

        try:
            x = quantity(value, unit, where)
        except ModelError as exc:
            raise ForwardError(where, exc.problem) from None
    elif isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ForwardError(where, f"must be a number or a '<number> <unit>' string, got {value!r}")
    else:
        x = float(value)
    if not np.isfinite(x):
        raise ForwardError(where, f"must be finite, got {x}")
    return x


def parameter_names(entries: Sequence[Entry]) -> list[str]:
    """Every parameter the entries are linear (or, for a tilt's azimuth, a warm-up's time
    constant and a lag, smooth) in."""
    out: list[str] = []
    for e in entries:
        for n in (e.parameter, e.azimuth_parameter, e.tau_parameter):
            if n and n not in out:
                out.append(n)
    return out


def parameters(entries: Sequence[Entry], exclude: set[str] | frozenset[str] = frozenset()) -> list[Parameter]:
    """The entries' parameters (value, SI unit, bounds: a series compliance that starts
    non-negative stays so, a time constant is positive, a lag within ±``MAX_LAG_S``), each
    once, skipping names in ``exclude``."""
    out: list[Parameter] = []
    seen = set(exclude)
    for e in entries:
        for nm, val, unit in ((e.parameter, e.value, parameter_unit(e)),
                              (e.azimuth_parameter, e.azimuth, "rad"),
                              (e.tau_parameter, e.tau, "s")):
            if nm and nm not in seen:
                lo, hi = _bounds(e, nm, val)
                out.append(Parameter(nm, val, unit, lo, hi))
                seen.add(nm)
    return out


def _bounds(e: Entry, name: str, value: float) -> tuple[float, float]:
    """Admissible range of parameter ``name`` of entry ``e`` at its current ``value``."""
    if name == e.tau_parameter:
        return 0.0, math.inf
    if e.kind == "lag" and name == e.parameter:
        return -MAX_LAG_S, MAX_LAG_S
    return (0.0 if e.kind == "series" and value >= 0 else -math.inf), math.inf


def cubic_bspline(u: np.ndarray) -> np.ndarray:
    """The uniform cubic B-spline B(u) ``(T,)`` [1] (knots at the integers, support |u| < 2,
    B(0) = 2/3, B(±1) = 1/6; twice continuously differentiable)."""
    a = np.abs(np.asarray(u, dtype=float))
    return np.where(a < 1.0, (4.0 - 6.0 * a**2 + 3.0 * a**3) / 6.0,
                    np.where(a < 2.0, (2.0 - a) ** 3 / 6.0, 0.0))


def _basis(e: Entry, t: np.ndarray) -> np.ndarray:
    """b(t) ``(T,)`` of a bias: 1, t [s], 1 − exp(−t/τ) (by ``expm1``: exact for t ≪ τ) or
    B(t/τ − k) − B(−k)."""
    t = np.asarray(t, dtype=float)
    if e.basis == "constant":
        return np.ones_like(t)
    if e.basis == "time":
        return t
    if e.basis == "spline":
        return cubic_bspline(t / e.tau - e.knot) - cubic_bspline(np.array(-float(e.knot)))
    return -np.expm1(-t / e.tau)


def _basis_dtau(e: Entry, t: np.ndarray) -> np.ndarray:
    """∂b/∂τ ``(T,)`` [1/s] of a warm-up basis: −(t/τ²) exp(−t/τ)."""
    t = np.asarray(t, dtype=float)
    return -(t / e.tau**2) * np.exp(-t / e.tau)


def _tilt(angle: float, azimuth: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotation R by ``angle`` about the in-plane axis k = (cos azimuth, sin azimuth, 0) and its
    analytic derivatives ∂R/∂angle, ∂R/∂azimuth (Rodrigues: R = I + sin a K + (1 − cos a) K²,
    K the cross-product matrix of k)."""
    def cross(k: np.ndarray) -> np.ndarray:
        return np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    sa, ca = np.sin(angle), np.cos(angle)
    K = cross(np.array([np.cos(azimuth), np.sin(azimuth), 0.0]))
    dK = cross(np.array([-np.sin(azimuth), np.cos(azimuth), 0.0]))
    K2 = K @ K
    R = np.eye(3) + sa * K + (1 - ca) * K2
    dRa = ca * K + sa * K2
    dRb = sa * dK + (1 - ca) * (dK @ K + K @ dK)
    return R, dRa, dRb


#: SI unit of an entry's parameter, by kind (bias: by channel and basis)
_BIAS_UNITS = {("tip_force", "constant"): "N", ("tip_force", "time"): "N/s", ("tip_force", "warmup"): "N",
               ("tip_force", "spline"): "N", ("tip_position", "constant"): "m",
               ("tip_position", "time"): "m/s", ("tip_position", "warmup"): "m",
               ("tip_position", "spline"): "m"}


def parameter_unit(entry: Entry) -> str:
    """The SI unit of ``entry.parameter`` (``"1"`` where skinkit's unit table has no name for it)."""
    if entry.kind == "bias":
        return _BIAS_UNITS.get((entry.channel, entry.basis), "m/s" if entry.basis == "time" else "m")
    if entry.kind == "lag":
        return "s"
    if entry.kind == "friction":
        return "N" if entry.channel == "tip_force" else "m"
    if entry.kind == "series":
        return "m/N" if (entry.channel, entry.source) == ("tip_position", "tip_force") else "1"
    if entry.kind == "tilt" or entry.mode == "rotation":
        return "rad"
    return "1"


def check_drive(entries: Sequence[Entry], channel: str) -> None:
    """Refuse entries a model driven by ``channel`` cannot honour (a series compliance on it);
    a model checks this when it is built, before any solve."""
    for e in entries:
        if e.kind == "series" and e.channel == channel:
            raise ForwardError(f"instrument ({e.parameter})",
                               f"a series compliance on the driving channel {channel!r} makes the drive "
                               "depend on the predicted force; drive the model by the tip force "
                               "([indenter] mode = \"force\") to include it")
        if e.kind == "friction" and e.channel == channel:
            raise ForwardError(f"instrument ({e.parameter})",
                               f"a friction on the driving channel {channel!r} makes the drive depend on "
                               f"the predicted {e.source!r}; drive the model by {e.source!r} to include it")


def drive(entries: Sequence[Entry], channel: str, time_s: np.ndarray, recorded: np.ndarray,
          names: Sequence[str] = ()) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """What the skin saw when ``channel`` recorded ``recorded`` ``(T, 3)`` at ``time_s`` ``(T,)``:
    lags of that channel undone, its biases removed, then a tilt applied. Returns the true
    drive ``(T, 3)`` and its derivatives ``(T, 3)`` for the parameters in ``names`` it depends on."""
    check_drive(entries, channel)
    x = np.array(recorded, dtype=float)
    d: dict[str, np.ndarray] = {}
    for e in reversed([e for e in entries if e.kind == "lag" and e.channel == channel]):
        x = _lagged(e, time_s, x, d, names, -1.0)    # the chain's output at t was recorded at t + lag
    for e in entries:
        if e.kind == "bias" and e.channel == channel:
            b = _basis(e, time_s)
            x[:, e.component] -= e.value * b
            if e.parameter in names:
                dd = d.setdefault(e.parameter, np.zeros_like(x))
                dd[:, e.component] -= b
            if e.tau_parameter and e.tau_parameter in names:
                dt = d.setdefault(e.tau_parameter, np.zeros_like(x))
                dt[:, e.component] -= e.value * _basis_dtau(e, time_s)
    for e in entries:
        if e.kind != "tilt":
            continue
        R, dRa, dRb = _tilt(e.value, e.azimuth)
        for k in list(d):
            d[k] = d[k] @ R.T
        if e.parameter in names:
            d[e.parameter] = d.get(e.parameter, 0) + x @ dRa.T
        if e.azimuth_parameter and e.azimuth_parameter in names:
            d[e.azimuth_parameter] = d.get(e.azimuth_parameter, 0) + x @ dRb.T
        x = x @ R.T
    return x, d


def measure(entries: Sequence[Entry], channel: str, time_s: np.ndarray, values: np.ndarray,
            d: Mapping[str, np.ndarray], channels: Mapping[str, tuple[np.ndarray, Mapping[str, np.ndarray]]],
            names: Sequence[str] = ()) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """What the instrument records of predicted ``channel``: ``values`` (the channel's shape)
    with derivatives ``d`` (name -> same shape). ``channels``: every channel the model knows
    (predicted or driving) as ``(values, derivatives)`` for ``series`` entries. Returns the
    recorded values and derivatives (the model's, carried through, plus the instrument's for
    the parameters in ``names``)."""
    v = np.array(values, dtype=float)
    out = {k: np.array(a, dtype=float) for k, a in d.items()}
    for e in entries:
        if e.kind == "bias" and e.channel == channel:
            v = _bias(e, time_s, v, out, names)
        elif e.kind == "series" and e.channel == channel:
            v = _series(e, channels, v, out, names)
        elif e.kind == "friction" and e.channel == channel:
            v = _friction(e, time_s, channels, v, out, names)
        elif e.kind == "similarity" and channel in _POINTS and e.channel in _POINTS:
            v = _similarity(e, v, out, names)
        elif e.kind == "tilt" and channel in _TIP:
            v = _tilted(e, v, out, names)
    for e in entries:
        if e.kind == "lag" and e.channel == channel:
            v = _lagged(e, time_s, v, out, names, 1.0)
    return v, out


def with_values(entries: Sequence[Entry], values: Mapping[str, float]) -> list[Entry]:
    """The entries with every parameter named in ``values`` (name -> SI value) set: ``value``,
    ``azimuth`` and ``tau`` by their parameter names. Bounds are not checked here."""
    out = []
    for e in entries:
        out.append(replace(e, value=float(values.get(e.parameter, e.value)),
                           azimuth=float(values.get(e.azimuth_parameter, e.azimuth)) if e.azimuth_parameter
                           else e.azimuth,
                           tau=float(values.get(e.tau_parameter, e.tau)) if e.tau_parameter else e.tau))
    return out


def similarity_parameters(entries: Sequence[Entry], channel: str) -> list[str]:
    """The parameters of the ``similarity`` entries on points channel ``channel``, in order."""
    return [e.parameter for e in entries if e.kind == "similarity" and e.channel == channel
            and channel in _POINTS]


def unrecord_points(entries: Sequence[Entry], channel: str, recorded: np.ndarray,
                    shift: Mapping[str, float] | None = None) -> np.ndarray:
    """Material positions ``(P, k)`` [m] of points whose recorded positions are ``recorded``
    ``(P, k)``: the ``similarity`` entries of ``channel`` undone, last first. ``shift``: parameter ->
    increment [SI] added to that entry's value (derivatives by differences of the embedding).

    Why: when a track's reference is one of its own frames, the tracker's calibration error
    distorts the reference as it does every other frame; the material points are where the
    undistorted reference puts them, and frame 0 is then recorded exactly as measured."""
    x = np.array(recorded, dtype=float)
    shift = shift or {}
    for e in reversed([e for e in entries if e.kind == "similarity" and e.channel == channel]):
        v = e.value + float(shift.get(e.parameter, 0.0))
        if e.mode == "scale":
            x = x / (1 + v)
        else:
            c, s = np.cos(v), np.sin(v)
            x[..., :2] = x[..., :2] @ np.array([[c, -s], [s, c]])     # the rotation's inverse
    return x


# Each step below takes the recorded values ``v`` so far and their derivatives ``out`` (updated
# in place, both copies made by measure), and returns the values after the entry ``e``.

def _bias(e: Entry, time_s: np.ndarray, v: np.ndarray, out: dict[str, np.ndarray],
          names: Sequence[str]) -> np.ndarray:
    """An offset (times its time basis) added to one component."""
    b = _basis(e, time_s)
    v[:, e.component] += e.value * b
    if e.parameter in names:
        out.setdefault(e.parameter, np.zeros_like(v))[:, e.component] += b
    if e.tau_parameter and e.tau_parameter in names:
        # entries of several components may share one time constant: their parts add up
        out.setdefault(e.tau_parameter, np.zeros_like(v))[:, e.component] += e.value * _basis_dtau(e, time_s)
    return v


def shift(time_s: np.ndarray, y: np.ndarray, delay: float) -> tuple[np.ndarray, np.ndarray]:
    """``y`` ``(T, ...)`` sampled at ``time_s`` ``(T,)`` [s], read ``delay`` [s] late:
    ``(y(t − delay), y′(t − delay))``, both ``(T, ...)``, y′ in [unit of y / s].

    Between samples y is the not-a-knot cubic spline through them (samples with a non-finite
    component and repeated times, after the first, are left out); outside the record it is
    held at the first or last sample, where y′ is 0. At ``delay = 0`` the values are ``y``
    itself (the null is exact, not merely interpolated)."""
    y = np.asarray(y, dtype=float)
    t = np.asarray(time_s, dtype=float)
    flat = y.reshape(t.size, -1)
    finite = np.all(np.isfinite(flat), axis=1)
    knots, first = np.unique(t[finite], return_index=True)
    if knots.size < 2:   # nothing to interpolate: a constant record
        return y.copy(), np.zeros_like(y)
    spline = CubicSpline(knots, flat[finite][first], axis=0)
    q = t - delay
    at = np.clip(q, knots[0], knots[-1])
    inside = (q >= knots[0]) & (q <= knots[-1])
    val = y.copy() if delay == 0 else spline(at).reshape(y.shape)
    der = (spline(at, 1) * inside[:, None]).reshape(y.shape)
    return val, der


def _lagged(e: Entry, time_s: np.ndarray, v: np.ndarray, out: dict[str, np.ndarray], names: Sequence[str],
            sign: float) -> np.ndarray:
    """The channel read ``sign · value`` late (``sign = 1``: as recorded; −1: the recording
    undone), the derivatives in ``out`` shifted alike and ∂/∂value = −sign · v′ added."""
    keys = list(out)
    stacked = np.stack([v, *(out[k] for k in keys)], axis=-1)
    val, der = shift(time_s, stacked, sign * e.value)
    for i, k in enumerate(keys):
        out[k] = val[..., i + 1].copy()
    if e.parameter in names:
        out[e.parameter] = out.get(e.parameter, np.zeros_like(v)) - sign * der[..., 0]
    return val[..., 0].copy()


def _source(e: Entry, channels: Mapping[str, tuple[np.ndarray, Mapping[str, np.ndarray]]]
            ) -> tuple[np.ndarray, Mapping[str, np.ndarray]]:
    """The values and derivatives of the channel entry ``e`` reads (an error naming the entry when
    the prediction lacks it)."""
    if e.source not in channels:
        raise ForwardError(f"instrument ({e.parameter})", f"needs the {e.source!r} channel")
    return channels[e.source]


def _series(e: Entry, channels: Mapping[str, tuple[np.ndarray, Mapping[str, np.ndarray]]],
            v: np.ndarray, out: dict[str, np.ndarray], names: Sequence[str]) -> np.ndarray:
    """Another channel, times the entry's value, added (e.g. crosstalk)."""
    sv, sd = _source(e, channels)
    sv = np.nan_to_num(np.asarray(sv, dtype=float))
    v = v + e.value * sv
    for k, a in sd.items():
        out[k] = out.get(k, np.zeros_like(v)) + e.value * a
    if e.parameter in names:
        out[e.parameter] = out.get(e.parameter, np.zeros_like(v)) + sv
    return v


def velocity(time_s: np.ndarray, y: np.ndarray, window: float) -> np.ndarray:
    """d``y``/dt ``(T, ...)`` of ``y`` ``(T, ...)`` sampled at ``time_s`` ``(T,)`` [s]: the
    Savitzky–Golay derivative (a local quadratic by least squares) over ``window`` [s], at least
    5 samples, on the median sampling step (the robot's channels are uniform). Linear in ``y``,
    exact for quadratics; the ends use the polynomial fitted to the first and last windows."""
    y = np.asarray(y, dtype=float)
    t = np.asarray(time_s, dtype=float)
    if t.size < 5:
        return np.gradient(y, t, axis=0) if t.size > 1 else np.zeros_like(y)
    dt = float(np.median(np.diff(t)))
    n = max(5, 2 * int(round(0.5 * window / dt)) + 1)
    n = min(n, t.size if t.size % 2 else t.size - 1)
    return savgol_filter(np.nan_to_num(y), n, 2, deriv=1, delta=dt, axis=0, mode="interp")


def _friction(e: Entry, time_s: np.ndarray,
              channels: Mapping[str, tuple[np.ndarray, Mapping[str, np.ndarray]]], v: np.ndarray,
              out: dict[str, np.ndarray], names: Sequence[str]) -> np.ndarray:
    """value · tanh(velocity of the source's component / v_s) added to the same component."""
    sv, sd = _source(e, channels)
    c = e.component
    vel = velocity(time_s, np.asarray(sv, dtype=float)[:, c], e.window)
    b = np.tanh(vel / e.velocity)
    v[:, c] += e.value * b
    if e.value != 0.0:
        gain = e.value * (1.0 - b**2) / e.velocity
        for k, a in sd.items():
            dd = out.setdefault(k, np.zeros_like(v))
            dd[:, c] += gain * velocity(time_s, np.asarray(a, dtype=float)[:, c], e.window)
    if e.parameter in names:
        out.setdefault(e.parameter, np.zeros_like(v))[:, c] += b
    return v


def _similarity(e: Entry, v: np.ndarray, out: dict[str, np.ndarray], names: Sequence[str]) -> np.ndarray:
    """Points scaled by ``1 + value``, or rotated in-plane by ``value`` [rad]."""
    if e.mode == "scale":
        for key in out:
            out[key] = (1 + e.value) * out[key]
        if e.parameter in names:
            out[e.parameter] = out.get(e.parameter, np.zeros_like(v)) + v
        return (1 + e.value) * v
    c, s = np.cos(e.value), np.sin(e.value)
    R2 = np.array([[c, -s], [s, c]])
    dR2 = np.array([[-s, -c], [c, -s]])
    xy = v[..., :2]
    for key in out:
        out[key][..., :2] = out[key][..., :2] @ R2.T
    if e.parameter in names:
        dd = out.get(e.parameter, np.zeros_like(v))
        dd[..., :2] += xy @ dR2.T
        out[e.parameter] = dd
    v[..., :2] = xy @ R2.T
    return v


def _tilted(e: Entry, v: np.ndarray, out: dict[str, np.ndarray], names: Sequence[str]) -> np.ndarray:
    """The probe's force and position seen in the robot frame of a tilted indenter."""
    R, dRa, dRb = _tilt(e.value, e.azimuth)
    # recorded (robot frame) = Rᵀ skin-frame, row by row: v @ R
    for key in out:
        out[key] = out[key] @ R
    if e.parameter in names:
        out[e.parameter] = out.get(e.parameter, np.zeros_like(v)) + v @ dRa
    if e.azimuth_parameter and e.azimuth_parameter in names:
        out[e.azimuth_parameter] = out.get(e.azimuth_parameter, np.zeros_like(v)) + v @ dRb
    return v @ R


__all__ = ["KINDS", "MAX_LAG_S", "Entry", "check_drive", "drive", "measure", "parameter_names",
           "parameter_unit", "parameters", "parse", "shift", "similarity_parameters", "unrecord_points",
           "velocity", "with_values"]
