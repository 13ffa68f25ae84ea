"""Instrument effects: linear transforms between what the skin saw and what was recorded
(``[[instrument]]`` entries, ``docs/guide/effects.md``), differentiated analytically by the forward
model. Each entry's ``parameter`` is the effect parameter itself, value 0 is no effect exactly.

``indenter-tilt`` and ``tracking-bias`` apply to finite-element models (a probe axis and 3D
points exist only there); ``force-offset``, ``force-drift``, ``force-warmup``, ``force-wander``,
``channel-lag`` and ``robot-compliance`` to any model; ``guide-friction`` to models driven by the
tip position (the lumped models).

Time t in these effects is each record's own, from its protocol's start (``Channel.time_s``): a
drift or a warm-up restarts at every protocol, as for a sensor zeroed (tared) at the start of
each record.
"""

from __future__ import annotations

from typing import Any

from skinkit.plugin.effects import BaseEffect, Declared, declare

_AXES = ("x", "y", "z")


class IndenterTilt(BaseEffect):
    """The probe's axis is misaligned: the drive acts along directions turned by ``angle`` [rad]
    (null 0) about the in-plane axis at ``azimuth`` [rad] from x. One ``tilt`` entry with
    ``parameter = "indenter-tilt.angle"`` and ``azimuth_parameter = "indenter-tilt.azimuth"``."""

    name = "indenter-tilt"
    kinds = ("fe",)
    touches = {"fe": frozenset({"instrument"})}

    def _declared(self) -> list[Declared]:
        return [declare("angle", 3.0, 0.0, "deg", -15.0, 15.0),
                declare("azimuth", 0.0, 0.0, "deg", -180.0, 180.0)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, [{"kind": "tilt", "parameter": f"{self.name}.angle", "value": v["angle"],
                                     "azimuth": v["azimuth"], "azimuth_parameter": f"{self.name}.azimuth"}])


class _ForceBias(BaseEffect):
    """Three ``bias`` entries on ``tip_force`` components 0, 1, 2 (parameters ``<effect>.x|y|z``)."""

    kinds = ("fe", "lumped")
    basis = "constant"

    def _entries(self, v: dict[str, float]) -> list[dict[str, Any]]:
        return [{"kind": "bias", "parameter": f"{self.name}.{a}", "value": v[a], "channel": "tip_force",
                 "component": i, "basis": self.basis} for i, a in enumerate(_AXES)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, self._entries(v))

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, self._entries(v))


class ForceOffset(_ForceBias):
    """A constant offset of the recorded tip force, ``x``, ``y``, ``z`` [N] (null 0): recorded =
    true + offset. On a force-driven model the skin saw recorded − offset."""

    name = "force-offset"
    touches = {"fe": frozenset({"instrument"}), "lumped": frozenset({"instrument"})}
    basis = "constant"

    def _declared(self) -> list[Declared]:
        return [declare(a, 20.0, 0.0, "mN", -1000.0, 1000.0) for a in _AXES]


class ForceDrift(_ForceBias):
    """A linear drift of the recorded tip force, ``x``, ``y``, ``z`` [N/s] (null 0): recorded =
    true + rate · t, t [s] the record's time from its protocol's start (the drift restarts at 0
    with every protocol: a sensor tared at each start). The typical 0.5 mN/s drifts by 15 mN
    over a 30 s protocol, about 9 force-noise levels (σ ≈ 1.7 mN), where 0.2 mN/s would stay
    below 5.

    This is the linear shape, the first term of any slow drift (a zero wandering with the room's
    temperature over minutes). A zero that settles, the exponential warm-up of a sensor's bridge
    and amplifier, is ``force-warmup``; over a protocol much shorter than its time constant the
    two look alike (A (1 − e^{−t/τ}) ≈ (A/τ) t) and the diagnosis reports them as not separable.
    Three ``bias`` entries with ``basis = "time"``."""

    name = "force-drift"
    touches = {"fe": frozenset({"instrument"}), "lumped": frozenset({"instrument"})}
    basis = "time"

    def _declared(self) -> list[Declared]:
        return [declare(a, 0.5, 0.0, "mN/s", -10.0, 10.0) for a in _AXES]


class ForceWarmup(_ForceBias):
    """The force sensor's zero settling after it was switched on or tared: recorded = true +
    A (1 − exp(−t/τ)) per axis, amplitudes ``x``, ``y``, ``z`` [N] (null 0) and one time
    constant ``tau`` [s], t the record's time from its protocol's start.

    Phenomenon: a strain-gauge load cell's bridge warms under its excitation current and its
    amplifier under its own dissipation, so the zero moves until both reach thermal equilibrium,
    to first order as a single-time-constant transient. Manufacturers of load cells and their
    amplifiers state a warm-up time for it, and the calibration of force-proving instruments
    (ISO 376) starts only once the instrument's temperature has stabilised.
    Taring at a protocol's start removes the offset reached so far: what remains within the
    protocol is again A′ (1 − e^{−t/τ}), with A′ = A e^{−t₀/τ} the part still to come. The
    effect takes one A′ for every protocol (exact for a single protocol, or for a transient
    that each taring or contact restarts). The typical 10 mN over τ = 10 s is about 6
    force-noise levels, settled within a 30 s protocol, so it is distinct from a linear drift.

    Not covered: one warm-up running across the whole session (A′ shrinking from protocol to
    protocol), several time constants, a zero that follows the room's temperature, creep of the
    reading under a held load, hysteresis between loading and unloading. ``force-drift`` is the
    linear shape.

    Three ``bias`` entries with ``basis = "warmup"``, sharing ``tau`` (``tau_parameter``). The
    amplitudes enter linearly; ∂/∂τ = −A (t/τ²) e^{−t/τ} analytically. At the null (A = 0) τ
    changes nothing: it has no signature there and the gap diagnosis holds it at its null
    (its typical value), identified only once the amplitudes are switched on."""

    name = "force-warmup"
    touches = {"fe": frozenset({"instrument"}), "lumped": frozenset({"instrument"})}
    basis = "warmup"

    def _declared(self) -> list[Declared]:
        return [*(declare(a, 10.0, 0.0, "mN", -1000.0, 1000.0) for a in _AXES),
                declare("tau", 10.0, 10.0, "s", 0.1, 3600.0)]

    def _entries(self, v: dict[str, float]) -> list[dict[str, Any]]:
        return [{**e, "tau": v["tau"], "tau_parameter": f"{self.name}.tau"} for e in super()._entries(v)]


class ForceWander(_ForceBias):
    """The force sensor's zero wandering slowly with temperature: recorded = true + w(t) per
    axis, w a cubic spline through 0 at t = 0, smooth on the scale of minutes:
    w(t) = Σ_k c_k [B(t/S − k) − B(−k)], k = 1 … :attr:`KNOTS`, B the uniform cubic B-spline,
    S = :attr:`SPACING` (100 s); coefficients ``x1`` … ``z3`` [N] (null 0), t the record's time
    from its protocol's start.

    Phenomenon: a strain-gauge load cell's zero moves with the temperature of its bridge, its
    adhesive and its amplifier (the manufacturer's "temperature effect on zero", in % of full
    scale per kelvin); in a room whose air conditioning cycles, near a window, a lamp or a
    person, that temperature swings over minutes, and the recorded force follows it with the
    sensor's thermal lag. The form assumes nothing of the swing's shape but its slowness: a
    spline with knots every S seconds holds wander whose features are slower than about 2S
    (a sinusoidal swing of period 150 s to 86 % of its variance over 243 s) and cannot follow
    a protocol's own loading, cycle by cycle (seconds to a minute): a softening that steps
    from one loading cycle to the next is not taken for a wandering zero.

    Not covered: wander with features faster than about 2S (it meets the protocol's own time
    scales and cannot be told from the tissue's response), wander after 3S = 300 s of a record
    (the last knot: the spline returns to a constant by 500 s), a zero that depends on the load
    (creep, hysteresis). ``force-drift`` (linear) and ``force-warmup`` (one exponential) are the
    shapes with one parameter per axis: over a short protocol the wander's first knot looks
    like either, and the diagnosis reports them as not separable.

    Three times :attr:`KNOTS` ``bias`` entries with ``basis = "spline"`` (``knot``, ``tau`` = S);
    linear in every coefficient."""

    name = "force-wander"
    touches = {"fe": frozenset({"instrument"}), "lumped": frozenset({"instrument"})}
    basis = "spline"
    #: knots of the spline (centred at S, 2S, … from the record's start)
    KNOTS = 3
    #: knot spacing S [s]
    SPACING = 100.0

    def _declared(self) -> list[Declared]:
        return [declare(f"{a}{k}", 2.0, 0.0, "mN", -1000.0, 1000.0)
                for a in _AXES for k in range(1, self.KNOTS + 1)]

    def _entries(self, v: dict[str, float]) -> list[dict[str, Any]]:
        return [{"kind": "bias", "parameter": f"{self.name}.{a}{k}", "value": v[f"{a}{k}"],
                 "channel": "tip_force", "component": i, "basis": self.basis, "knot": k, "tau": self.SPACING}
                for i, a in enumerate(_AXES) for k in range(1, self.KNOTS + 1)]


class ChannelLag(BaseEffect):
    """The force channel recorded ``lag`` [s] late relative to the position channel and the
    cameras (null 0, typical 10 ms, admissible ±0.5 s): recorded force(t) = true force(t − lag).

    Phenomenon: force and position are sampled by different electronics (a force transducer's
    acquisition card, the robot's controller) whose clocks and buffering are not synchronised:
    a constant skew of a few milliseconds between the channels is common unless the devices
    share a hardware trigger or a synchronised clock (IEEE 1588). It turns a hysteresis-free
    skin into an apparently dissipative one: a loop in force against position whose area grows
    with the rate.

    Form: one ``lag`` instrument entry on ``tip_force``. The shifted force is the not-a-knot
    cubic spline through the predicted force samples, read at t − lag (held at the first or last
    sample outside the record); ∂/∂lag = −f′(t − lag), the spline's own derivative. On a model
    driven by force (the finite-element models by default) the drive is the recorded force read
    lag later. Tracked points are not shifted; a positive lag means the force is late.

    Not covered: a lag that varies in time (clocks running at different rates, so the skew
    grows through a record, or jitter from sample to sample), the frequency-dependent phase of
    an anti-aliasing filter (not a pure delay), a lag of the cameras relative to the robot."""

    name = "channel-lag"
    kinds = ("fe", "lumped")
    touches = {"fe": frozenset({"instrument"}), "lumped": frozenset({"instrument"})}

    def _declared(self) -> list[Declared]:
        return [declare("lag", 10.0, 0.0, "ms", -500.0, 500.0)]

    def _entries(self, v: dict[str, float]) -> list[dict[str, Any]]:
        return [{"kind": "lag", "parameter": f"{self.name}.lag", "value": v["lag"], "channel": "tip_force"}]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, self._entries(v))

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, self._entries(v))


class RobotCompliance(BaseEffect):
    """A series compliance between the motor and the tip, ``compliance`` [m/N] (null 0): the
    recorded tip position is the true one plus compliance · tip force. One ``series`` entry on
    ``tip_position`` with source ``tip_force``."""

    name = "robot-compliance"
    kinds = ("fe", "lumped")
    touches = {"fe": frozenset({"instrument"}), "lumped": frozenset({"instrument"})}

    def _declared(self) -> list[Declared]:
        return [declare("compliance", 1.0, 0.0, "mm/N", 0.0, 10.0)]

    def _entries(self, v: dict[str, float]) -> list[dict[str, Any]]:
        return [{"kind": "series", "parameter": f"{self.name}.compliance", "value": v["compliance"],
                 "channel": "tip_position", "source": "tip_force"}]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, self._entries(v))

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, self._entries(v))


class GuideFriction(BaseEffect):
    """Friction in a guide between the force sensor and the skin, read by the force sensor:
    recorded force = true + f · tanh(v/v_s) per axis, levels ``x``, ``y``, ``z`` [N] (null 0), v
    the tip's velocity along that axis.

    Phenomenon: the probe's arm runs in linear guides or slides, and a linear potentiometer's
    wiper rubs on its track; where such a contact lies between the force sensor and the skin, the
    sensor reads the skin's force plus a friction that opposes the motion and hardly depends on
    its speed. The thesis this project follows found friction in its robot's linear guides and
    potentiometers, different from motor to motor (worn bearings raised it; the guides were
    redesigned to reduce it), and tangential stretches recruit the moving platform's slides,
    which normal indentation leaves idle. At one rate it draws a loop in force against stretch
    whose height (2f) does not grow with the rate: a relaxation's loop does.

    Form: Coulomb's law, regularised: sign(v) smoothed over v_s = :attr:`VELOCITY` (0.1 mm/s, a
    tenth of a slow ramp's speed) and v estimated from the recorded tip position by a
    Savitzky–Golay derivative over :attr:`WINDOW` (0.1 s; the encoder's noise, about 1.6 µm,
    gives a velocity noise of about 15 µm/s there, so the sign does not flicker at rest). Three
    ``friction`` instrument entries on ``tip_force``, linear in each level.

    Not covered: a static friction above the kinetic one or a force that falls with speed
    (Stribeck), a presliding stiffness (Dahl, LuGre: over a transition shorter than about
    v_s times the window this form is the same), a viscous part (a damper: taken by the model's
    own damping or relaxation), friction that depends on the normal load. Applies to models
    driven by the tip position (the lumped models); a finite-element model driven by the
    recorded force would need the drive solved with the friction (refused there, as a series
    compliance on the driving channel is)."""

    name = "guide-friction"
    kinds = ("lumped",)
    touches = {"lumped": frozenset({"instrument"})}
    #: sign-smoothing velocity v_s [m/s] and velocity-estimate window [s]
    VELOCITY = 1e-4
    WINDOW = 0.1

    def _declared(self) -> list[Declared]:
        return [declare(a, 5.0, 0.0, "mN", -1000.0, 1000.0) for a in _AXES]

    def _entries(self, v: dict[str, float]) -> list[dict[str, Any]]:
        return [{"kind": "friction", "parameter": f"{self.name}.{a}", "value": v[a], "channel": "tip_force",
                 "component": i, "source": "tip_position", "velocity": self.VELOCITY, "window": self.WINDOW}
                for i, a in enumerate(_AXES)]

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, self._entries(v))


class TrackingBias(BaseEffect):
    """A calibration error of the 3D points: a relative ``scale`` error [1] and a ``rotation`` [rad]
    about the normal through the session origin (both null 0). Two ``similarity`` entries on
    ``points`` (``mode = "scale"`` and ``"rotation"``)."""

    name = "tracking-bias"
    kinds = ("fe",)
    touches = {"fe": frozenset({"instrument"})}

    def _declared(self) -> list[Declared]:
        return [declare("scale", 1.0, 0.0, "%", -10.0, 10.0),
                declare("rotation", 0.5, 0.0, "deg", -5.0, 5.0)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, [
            {"kind": "similarity", "parameter": f"{self.name}.{m}", "value": v[m], "channel": "points",
             "mode": mode} for m, mode in (("scale", "scale"), ("rotation", "rotation"))])


__all__ = ["ChannelLag", "ForceDrift", "ForceOffset", "ForceWarmup", "ForceWander", "GuideFriction",
           "IndenterTilt", "RobotCompliance", "TrackingBias"]
