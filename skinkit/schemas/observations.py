"""What a session measured, channel by channel, and what a forward model predicts of it.

Frames: every channel is in the **skin frame** — origin at the probe's contact point, x and y
in the skin plane (the robot's x and y), z along the outward normal of the skin. The robot
frame has z *into* the skin; :func:`skinkit.observe.read_observations` flips it, so that a
finite-element model (top surface at z = 0, tissue below) and the data agree without any
sign convention left to the user. ``tip_force`` is the force the probe applies to the skin.

Channel shapes (T = samples of the channel, P = points):

* ``tip_force`` ``(T, 3)`` [N], ``tip_position`` ``(T, 3)`` [m] (displacement of the tip from
  its contact position);
* ``points`` ``(P, T, 3)`` [m]: positions of tracked material points;
* ``points_2d`` ``(P, T, 2)`` [m]: in-plane positions where only 2D tracking exists.

``valid`` has the shape of ``values`` (False where a component was not measured or a point
was lost); ``noise`` is the standard deviation of one sample of each component, shape
``(3,)`` or ``(2,)``, in the channel's unit, with ``noise_source`` saying how it was
estimated.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.errors import SchemaError
from skinkit.schemas import display
from skinkit.schemas.protocol import Protocol
from skinkit.schemas.surface import SurfaceProfile

#: channel name -> (SI unit, number of leading point axes, components)
CHANNELS: dict[str, tuple[str, int, int]] = {
    "tip_force": ("N", 0, 3),
    "tip_position": ("m", 0, 3),
    "points": ("m", 1, 3),
    "points_2d": ("m", 1, 2),
}


@dataclass
class Channel:
    """One observed quantity of one protocol.

    Attributes:
        name: one of :data:`CHANNELS`.
        time_s: ``(T,)`` sample times [s] from the protocol's start, non-decreasing.
        values: ``(T, 3)`` for tip channels, ``(P, T, k)`` for point channels [unit].
        valid: bool, the shape of ``values``.
        noise: ``(k,)`` standard deviation of one sample per component [unit], positive.
        noise_source: how ``noise`` was estimated (``"rest segment"``, ``"tracker"``, ...).
        reference: ``(P, 3)`` [m] reference (undeformed) positions of point channels, or None.
        reference_frame: the frame whose measured positions are ``reference`` (0 for a track
            read from a session), or None when the reference is known exactly. A measured
            reference carries that frame's noise into every later frame's residual; see
            :meth:`whiten`.
        window_m: side [m] of the square of skin a point channel's value averages over (a
            subset tracker follows the mean motion of its subset, not its centre's), or None
            for a material point.
        noise_ar: for a tip channel whose noise is coloured, per component the ``(p,)``
            coefficients of its autoregressive model (an empty array: white), or None (all
            white); see :mod:`skinkit.forward.noise_model`.
        noise_innovation: ``(k,)`` standard deviation of the AR model's white innovation
            [unit] (None: equal to ``noise``).
        outliers: bool, the shape of ``values``: samples flagged as isolated spikes (they are
            also not ``valid``), or None.
        noise_scale: the shape of ``values``: for a tip channel, the AR innovation's standard
            deviation at each sample over ``noise_innovation`` (≥ 1: a sensor noisier under
            load than at rest); for a point channel, each position's standard error over
            ``noise`` (a tracker's error grows with the deformation it reads); None: 1.
    """

    name: str
    time_s: Any
    values: Any
    valid: Any = None
    noise: Any = None
    noise_source: str = "unknown"
    reference: Any = None
    reference_frame: int | None = None
    window_m: float | None = None
    noise_ar: Any = None
    noise_innovation: Any = None
    outliers: Any = None
    noise_scale: Any = None

    def __post_init__(self) -> None:
        if self.name not in CHANNELS:
            raise SchemaError("Channel.name", f"must be one of {sorted(CHANNELS)}, got {self.name!r}")
        unit, lead, k = CHANNELS[self.name]
        f = f"Channel[{self.name}]"
        self.time_s = np.asarray(self.time_s, dtype=float)
        if self.time_s.ndim != 1 or not np.all(np.isfinite(self.time_s)):
            raise SchemaError(f"{f}.time_s", "must be a finite (T,) array")
        if np.any(np.diff(self.time_s) < 0):
            raise SchemaError(f"{f}.time_s", "must be non-decreasing")
        v = np.asarray(self.values, dtype=float)
        T = self.time_s.size
        want = (T, k) if lead == 0 else (None, T, k)
        if v.ndim != len(want) or any(w is not None and w != s for w, s in zip(want, v.shape, strict=True)):
            shape = f"(T, {k})" if lead == 0 else f"(P, T, {k})"
            raise SchemaError(f"{f}.values", f"expected shape {shape} with T = {T}, got {v.shape}")
        self.values = v
        if self.valid is None:
            self.valid = np.isfinite(v)
        else:
            self.valid = np.broadcast_to(np.asarray(self.valid, dtype=bool), v.shape).copy()
        if np.any(~np.isfinite(v[self.valid])):
            raise SchemaError(f"{f}.values", "a value marked valid is not finite")
        if self.noise is None:
            raise SchemaError(f"{f}.noise", "a noise level per component is required")
        nz = np.broadcast_to(np.asarray(self.noise, dtype=float), (k,)).copy()
        if not np.all(np.isfinite(nz)) or np.any(nz <= 0):
            raise SchemaError(f"{f}.noise", f"must be positive and finite, got {nz.tolist()}")
        self.noise = nz
        if self.window_m is not None:
            w = float(self.window_m)
            if not (math.isfinite(w) and w > 0):
                raise SchemaError(f"{f}.window_m", f"must be positive and finite, got {self.window_m!r}")
            self.window_m = w
        self._check_noise_model(f, k)
        if self.noise_scale is not None:
            sc = np.asarray(self.noise_scale, dtype=float)
            if sc.shape != self.values.shape or not np.all(np.isfinite(sc)) or np.any(sc <= 0):
                raise SchemaError(f"{f}.noise_scale", f"must be positive, finite and {self.values.shape}")
            self.noise_scale = sc
        if self.reference is not None:
            ref = np.asarray(self.reference, dtype=float)
            if lead == 0 or ref.shape != (v.shape[0], 3):
                raise SchemaError(f"{f}.reference", f"expected (P, 3) for a point channel, got {ref.shape}")
            self.reference = ref

    def __repr__(self) -> str:
        """Two lines: name, unit, shape, valid samples, time span, noise (never the arrays)."""
        return "\n".join(display.channel_lines(self))

    def _check_noise_model(self, f: str, k: int) -> None:
        """Validate ``noise_ar`` and ``noise_innovation`` (``f``: the channel's entry name)."""
        if self.noise_ar is None:
            return
        if self.is_points or len(self.noise_ar) != k:
            raise SchemaError(f"{f}.noise_ar", f"one AR coefficient array per component ({k}) "
                              "of a tip channel")
        self.noise_ar = tuple(np.asarray(a, dtype=float).ravel() for a in self.noise_ar)
        inn = self.noise if self.noise_innovation is None else \
            np.broadcast_to(np.asarray(self.noise_innovation, dtype=float), (k,)).copy()
        if not np.all(np.isfinite(inn)) or np.any(inn <= 0):
            raise SchemaError(f"{f}.noise_innovation", f"must be positive and finite, got {inn.tolist()}")
        self.noise_innovation = inn

    @property
    def unit(self) -> str:
        """The channel's SI unit."""
        return CHANNELS[self.name][0]

    @property
    def is_points(self) -> bool:
        """True for a channel of tracked points (values (P, T, k)) rather than one (T, k) series."""
        return CHANNELS[self.name][1] == 1

    @property
    def n_valid(self) -> int:
        """Number of valid samples."""
        return int(self.valid.sum())

    def fit_mask(self, predicted: np.ndarray | None = None) -> np.ndarray:
        """Entries that carry information: valid, predicted (if a mask is given), and not the
        reference frame itself (whose residual is zero by construction)."""
        m = self.valid.copy() if predicted is None else self.valid & predicted
        if self.is_points and self.reference_frame is not None:
            m[:, self.reference_frame] = False
        return m

    @property
    def coloured(self) -> bool:
        """True when some component's noise has an autoregressive model."""
        return self.noise_ar is not None and any(a.size for a in self.noise_ar)

    def _by_component(self, a: np.ndarray, mask: np.ndarray, inverse: bool) -> np.ndarray:
        """Prewhiten (or colour, ``inverse``) a tip channel's ``(T, k)`` array per component."""
        from skinkit.schemas.ar_filter import colour_series, whiten_series

        out = np.array(np.where(mask, a, 0.0), copy=True)
        for j, ar in enumerate(self.noise_ar):
            if ar.size:
                ratio = float(self.noise[j] / self.noise_innovation[j])
                fn = colour_series if inverse else whiten_series
                sc = None if self.noise_scale is None else self.noise_scale[:, j]
                out[:, j] = fn(out[:, j], mask[:, j], ar, ratio, sc)
        return np.where(mask, out, 0.0)

    def sigma(self) -> np.ndarray:
        """Each entry's noise standard deviation [unit], the shape of ``values``: the
        component's level, times ``noise_scale`` for a point channel (a tip channel's scale
        acts on its AR innovation, inside :meth:`whiten`)."""
        s = np.broadcast_to(self.noise, self.values.shape)
        if self.is_points and self.noise_scale is not None:
            return s * self.noise_scale
        return s

    def _frame_weights(self, mask: np.ndarray) -> np.ndarray:
        """``(P, T, k)`` v = σ(reference frame) / σ(frame) on ``mask``, 0 elsewhere (see
        :meth:`whiten`)."""
        if self.noise_scale is None:
            return mask.astype(float)
        sc = self.noise_scale
        rf = int(self.reference_frame)
        return np.where(mask, sc[:, rf:rf + 1, :] / sc, 0.0)

    def whiten(self, a: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """Decorrelate noise-normalised residuals (or their derivatives) ``a``.

        A tip channel with coloured noise (``noise_ar``) is prewhitened along time per component
        (:func:`skinkit.forward.noise_model.whiten_series`): Σ r² is then χ² under its noise model.
        For points, along frames:

        When the reference positions are the measured frame ``reference_frame``, a point's
        residuals over its other m frames share that frame's noise. Normalised by each frame's
        own σ (:meth:`sigma`) their covariance is I + vvᵀ, v = σ(reference) / σ(frame) (v = 1
        when every frame has the same level). Multiplying by
        (I + vvᵀ)^(-1/2) = I − (1 − 1/√(1+|v|²)) vvᵀ/|v|² makes them independent standard
        normals again, so Σ r² is χ² with m degrees of freedom per point and component.
        Linear in ``a`` (Jacobians go through the same map). Other channels are returned
        unchanged."""
        return self._frames(a, mask, inverse=False)

    def unwhiten(self, a: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`whiten`: multiply by (I + vvᵀ)^(1/2) = I + (√(1+|v|²) − 1) vvᵀ/|v|²
        along frames (residuals that whiten to ``a``), or colour a tip channel's samples with its
        noise model; other channels unchanged."""
        return self._frames(a, mask, inverse=True)

    def _frames(self, a: np.ndarray, mask: np.ndarray, inverse: bool) -> np.ndarray:
        if self.coloured:
            return self._by_component(a, mask, inverse=inverse)
        if not self.is_points or self.reference_frame is None:
            return a
        a = np.where(mask, a, 0.0)
        v = self._frame_weights(mask)
        q = np.sum(v * v, axis=1)                             # (P, k)
        s = np.sum(v * a, axis=1)
        root = np.sqrt(1 + q)
        with np.errstate(invalid="ignore", divide="ignore"):
            gain = (root - 1) if inverse else -(1 - 1 / root)
            c = np.where(q > 0, gain * s / np.maximum(q, 1e-300), 0.0)
        return np.where(mask, a + c[:, None, :] * v, 0.0)

    def normalised(self, predicted: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """``(predicted - values) / sigma`` on ``mask`` (default :meth:`fit_mask`), whitened
        along frames (:meth:`whiten`), 0 elsewhere; shape of ``values``."""
        mask = self.fit_mask() if mask is None else mask
        r = np.where(mask, (np.asarray(predicted) - np.where(mask, self.values, 0.0)), 0.0)
        return self.whiten(r / self.sigma(), mask)


@dataclass
class ProtocolObservations:
    """Everything measured during one protocol.

    Attributes:
        protocol: what the robot was asked to do.
        channels: channel name -> :class:`Channel`.
        held_out: True when the protocol is kept for validation (not for fitting).
    """

    protocol: Protocol
    channels: dict[str, Channel] = field(default_factory=dict)
    held_out: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.protocol, Protocol):
            raise SchemaError("ProtocolObservations.protocol", "must be a Protocol")
        for k, c in self.channels.items():
            if not isinstance(c, Channel) or c.name != k:
                raise SchemaError(f"ProtocolObservations[{self.name}].channels[{k!r}]",
                                  "must be a Channel of that name")

    def __repr__(self) -> str:
        """One line: the protocol, its kind and duration, each channel's shape and noise."""
        return "ProtocolObservations " + display.protocol_line(self)

    @property
    def name(self) -> str:
        """The protocol's name."""
        return self.protocol.name

    @property
    def duration_s(self) -> float:
        """The last observed time [s] over the channels (0 with none)."""
        return max((float(c.time_s[-1]) for c in self.channels.values() if c.time_s.size), default=0.0)

    def channel(self, name: str) -> Channel:
        """The channel ``name``; a clear error naming the protocol when it is missing."""
        try:
            return self.channels[name]
        except KeyError:
            raise SchemaError(f"session protocol {self.name!r}",
                              f"has no {name!r} channel (it has {sorted(self.channels)})") from None


@dataclass
class Observations:
    """A session's measurements: protocols in recorded order, and the undeformed surface.

    Attributes:
        protocols: protocol name -> :class:`ProtocolObservations` (insertion order = session order).
        profile: the profiled undeformed surface the points were embedded in, or None.
        source: where the observations came from (a file path).
    """

    protocols: dict[str, ProtocolObservations]
    profile: SurfaceProfile | None = None
    source: str = ""
    #: the model's discretisation error carried as noise (an
    #: :class:`skinkit.inverse.approximation.ModelError`), or None
    model_error: Any = None

    def __post_init__(self) -> None:
        for k, p in self.protocols.items():
            if not isinstance(p, ProtocolObservations) or p.name != k:
                raise SchemaError(f"Observations.protocols[{k!r}]",
                                  "must be ProtocolObservations of that name")

    def __repr__(self) -> str:
        """A few lines: the source, one per protocol (channels, shapes, noise), never the arrays."""
        return "\n".join(display.observations_lines(self))

    def __iter__(self) -> Iterator[ProtocolObservations]:
        return iter(self.protocols.values())

    def __len__(self) -> int:
        return len(self.protocols)

    def __getitem__(self, name: str) -> ProtocolObservations:
        try:
            return self.protocols[name]
        except KeyError:
            raise SchemaError("session",
                              f"has no protocol {name!r} (it has {list(self.protocols)})") from None

    @property
    def names(self) -> list[str]:
        """The protocols' names."""
        return list(self.protocols)

    def select(self, names: Sequence[str]) -> Observations:
        """The observations of ``names`` only (in session order); unknown names are an error."""
        for n in names:
            self[n]
        keep = set(names)
        return Observations({k: v for k, v in self.protocols.items() if k in keep}, self.profile, self.source,
                            self.model_error)

    def with_held_out(self, names: Sequence[str]) -> Observations:
        """A copy with exactly ``names`` marked held out."""
        for n in names:
            self[n]
        return Observations({k: ProtocolObservations(v.protocol, v.channels, k in set(names))
                             for k, v in self.protocols.items()}, self.profile, self.source,
                            self.model_error)

    def until(self, t_s: float, option: str = "--until") -> Observations:
        """Every channel cut to its samples at times ≤ ``t_s`` [s] (a record's first part). A cut
        that leaves a protocol no channel of 2 samples or more is refused naming ``option``, the
        value and the protocol's time span: the session is not to blame for it."""
        out = {}
        cuts: dict[tuple[str, str], tuple[slice, ...]] = {}
        for p in self:
            chans = {}
            for c in p.channels.values():
                k = int(np.searchsorted(c.time_s, t_s, side="right"))
                if k < 2:
                    continue
                sl = (slice(None), slice(0, k)) if c.is_points else (slice(0, k),)
                cuts[(p.name, c.name)] = sl
                chans[c.name] = Channel(c.name, c.time_s[:k], c.values[sl], c.valid[sl], c.noise,
                                        c.noise_source, c.reference, c.reference_frame, c.window_m,
                                        c.noise_ar, c.noise_innovation,
                                        None if c.outliers is None else c.outliers[sl],
                                        None if c.noise_scale is None else c.noise_scale[sl])
            if p.channels and not chans:
                t0 = min(float(c.time_s[0]) for c in p.channels.values() if c.time_s.size)
                t1 = max(float(c.time_s[-1]) for c in p.channels.values() if c.time_s.size)
                raise SchemaError(f"{option} {t_s:g} s", f"leaves no samples of protocol {p.name!r} "
                                  f"(its record spans {t0:g} to {t1:g} s; the cut keeps a channel "
                                  "only with 2 samples or more)")
            out[p.name] = ProtocolObservations(p.protocol, chans, p.held_out)
        err = None if self.model_error is None else self.model_error.cut(cuts)
        return Observations(out, self.profile, self.source, err)

    def fitted(self) -> Observations:
        """The protocols that are fitted (not held out)."""
        return Observations({k: v for k, v in self.protocols.items() if not v.held_out},
                            self.profile, self.source, self.model_error)

    def held_out(self) -> Observations:
        """The held-out protocols."""
        return Observations({k: v for k, v in self.protocols.items() if v.held_out},
                            self.profile, self.source, self.model_error)

    def with_model_error(self, error: Any) -> Observations:
        """A copy whose residuals carry ``error`` (the model's discretisation error, mean and
        covariance: :mod:`skinkit.inverse.approximation`; None: none)."""
        return Observations(dict(self.protocols), self.profile, self.source, error)

    def summary(self) -> dict[str, Any]:
        """JSON-ready overview: per protocol, its channels with shapes and noise."""
        return {"source": self.source,
                "profile_points": None if self.profile is None else self.profile.n_points,
                "protocols": {p.name: {"held_out": p.held_out, "channels": {
                    c.name: {"shape": list(c.values.shape), "unit": c.unit, "noise": c.noise.tolist(),
                             "noise_source": c.noise_source, "valid": c.n_valid}
                    for c in p.channels.values()}} for p in self}}


@dataclass
class ChannelPrediction:
    """A forward model's prediction of one channel.

    Attributes:
        values: the shape of the observed channel's ``values`` [unit].
        d: parameter name -> derivative, each the shape of ``values`` [unit per parameter SI unit].
        predicted: bool, the shape of ``values``: entries the model predicts (None: all). A
            frictionless indenter, for example, predicts no in-plane tip motion.
    """

    values: np.ndarray
    d: dict[str, np.ndarray] = field(default_factory=dict)
    predicted: np.ndarray | None = None

    def __repr__(self) -> str:
        """One line: the shape, the entries predicted, the parameters with derivatives."""
        return display.channel_prediction_line(self)

    def mask(self, channel: Channel) -> np.ndarray:
        """Entries that are observed (valid), predicted, and not a measured reference frame."""
        return channel.fit_mask(self.predicted)


@dataclass
class Prediction:
    """Predictions of every channel a forward model predicts, protocol by protocol.

    Attributes:
        protocols: protocol -> channel -> :class:`ChannelPrediction`.
        methods: parameter name -> how its derivatives were obtained (``"analytic"``,
            ``"complex-step"``, ``"central-difference"``); empty without sensitivities.
        inputs: protocol -> the channel that drove the model (not predicted).
        info: solver figures (wall time, Newton iterations per step, ...).
    """

    protocols: dict[str, dict[str, ChannelPrediction]]
    methods: dict[str, str] = field(default_factory=dict)
    inputs: dict[str, str] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)

    def __repr__(self) -> str:
        """A few lines: per protocol the channels predicted and their shapes (never the arrays)."""
        return "\n".join(display.prediction_lines(self))

    def items(self) -> Iterator[tuple[str, str, ChannelPrediction]]:
        """``(protocol, channel, prediction)`` in order."""
        for p, chans in self.protocols.items():
            for c, cp in chans.items():
                yield p, c, cp

    def chi2(self, observations: Observations) -> tuple[float, int]:
        """``(Σ normalised residual², number of valid samples)`` over every predicted channel."""
        s, n = 0.0, 0
        for p, c, cp in self.items():
            ch = observations[p].channels[c]
            m = cp.mask(ch)
            r = ch.normalised(cp.values, m)
            s += float(np.sum(r[m] ** 2))
            n += int(m.sum())
        return s, n


def as_observations(obj: Any) -> Observations:
    """``obj`` if it is :class:`Observations`; a clear error otherwise."""
    if not isinstance(obj, Observations):
        raise SchemaError("observations", f"expected Observations, got {type(obj).__name__}")
    return obj


__all__ = ["CHANNELS", "Channel", "ChannelPrediction", "Observations", "Prediction",
           "ProtocolObservations", "as_observations"]
