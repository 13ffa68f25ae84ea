"""The interfaces plugins implement.

A plugin is registered under one of the entry-point groups in :data:`GROUPS` and points at
a class (or any object) that provides the members its interface lists. The registry checks
those members when it loads the plugin and reports what is missing. Interfaces are
structural (each is a ``typing.Protocol``): a plugin never needs to import or subclass
anything from skinkit to satisfy one, although it may use the plugin surface skinkit offers,
:mod:`skinkit.plugin`, and check itself with its conformance kits
(``docs/guide/writing-plugins.md``). In skinkit "protocol" alone means a measurement protocol
(:class:`skinkit.schemas.Protocol`), which drivers run.

Shapes and units follow the schemas: SI inside, arrays as numpy.
"""

from __future__ import annotations

import typing
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, runtime_checkable

import numpy as np

from skinkit.schemas import (
    CameraRig,
    ImageSequence,
    Parameter,
    ParameterSet,
    Protocol,
    RobotRecord,
    SurfaceProfile,
)


@runtime_checkable
class Driver(typing.Protocol):
    """A robot driver (``skinkit.drivers``): talks to a device, real or simulated.

    Lifecycle: ``connect`` -> ``home`` -> ``run`` (any number) -> ``disconnect``.
    ``emergency_stop`` may be called at any time, from any thread, and must leave the robot
    de-energised.

    Optional, for ``skinkit bench robot``: ``wire_bits_per_sample`` (bits a streamed sample
    costs on the link, framing included [bit]) and ``line_rate_option`` (the ``connect``
    option that sets the link's rate [bit/s or baud]); without them the link's capacity is
    reported as unknown.
    """

    name: str

    def connect(self, **options: Any) -> None:
        """Open the link (``options`` are driver specific, e.g. ``port``, ``bitrate``)."""

    def home(self, contact_force_N: float = 0.01) -> None:
        """Zero positions, then approach until the tip force reaches ``contact_force_N`` [N]."""

    def run(self, protocol: Protocol) -> Iterator[RobotRecord]:
        """Execute ``protocol``; yield its samples block by block as they arrive.

        Refuses, before any motion, a protocol that would exceed a safety limit.
        """

    def emergency_stop(self) -> None:
        """De-energise the motors now."""

    def disconnect(self) -> None:
        """Leave the robot safe and close the link."""


@runtime_checkable
class Tracker(typing.Protocol):
    """A 2D subset tracker (``skinkit.trackers``).

    ``track(reference, current, points, subset_px, mask)`` with ``reference`` and
    ``current`` ``(H, W)`` grey images, ``points`` ``(N, 2)`` pixel coordinates ``(x, y)`` in
    the reference (origin at the centre of the top-left pixel), ``subset_px`` the subset
    side [px] and ``mask`` an optional ``(H, W)`` bool array of usable pixels. Returns a
    :class:`TrackResult`-like object with ``displacement_px`` ``(N, 2)``, ``quality`` ``(N,)``,
    ``valid`` ``(N,)`` bool and ``reason`` (list of N strings, empty where valid).
    """

    name: str

    def track(self, reference: np.ndarray, current: np.ndarray, points: np.ndarray,
              subset_px: int = 64, mask: np.ndarray | None = None) -> Any:
        """Displacements of ``points`` (N, 2) [px] from ``reference`` to ``current`` (see the class)."""


@runtime_checkable
class Profiler(typing.Protocol):
    """A surface profiler (``skinkit.profilers``): undeformed views -> :class:`SurfaceProfile`.

    Optional: ``options``, a mapping keyword -> one-line description (with its unit) of the
    keyword options the profiler's constructor accepts; ``skinkit vision profile`` passes its
    ``--spacing`` (``spacing_px``) and ``--subset`` (``subset_px``) only to a profiler that
    declares them, and refuses them, when given, for one that does not.
    """

    name: str

    def profile(self, images: ImageSequence, rig: CameraRig, frame: int = 0) -> SurfaceProfile:
        """The surface of frame ``frame`` of ``images`` seen by ``rig``, in the rig's frame [m]."""


@runtime_checkable
class Law(typing.Protocol):
    """A constitutive law (``skinkit.laws``).

    A law declares its parameters and its strain-energy density; the finite-element engine
    derives the second Piola-Kirchhoff stress and the material tangent from the energy when
    the law does not provide them (optional methods ``stress(C, p)`` -> ``(..., 3, 3)`` [Pa]
    and ``tangent(C, p)`` -> ``(..., 3, 3, 3, 3)`` [Pa]).

    ``energy(C, p)``: ``C`` is ``(..., 3, 3)`` right Cauchy-Green tensor [1], ``p`` a mapping
    parameter name -> SI value (arrays broadcastable against ``C[..., 0, 0]`` allowed);
    returns ``(...)`` strain-energy density [Pa = J/m³].

    Optional: ``verification_cases()`` (callable on the registered object, so a static or
    class method when a class is registered): the cases ``skinkit verify`` runs for the law,
    a list of mappings with ``name``, ``options``, ``parameters``, ``checks`` and
    ``prestress`` (see :mod:`skinkit.fem.verify`).
    """

    name: str

    def parameters(self) -> Sequence[Parameter]:
        """Declared parameters with units, default values and admissible bounds."""

    def energy(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Strain-energy density W (...) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""


@runtime_checkable
class Optimiser(typing.Protocol):
    """An optimiser (``skinkit.optimisers``) for bound-constrained least squares or scalar goals.

    ``minimise(fun, x0, lower, upper, jac=None, options=None)``: ``fun(x)`` returns the
    residual vector ``(m,)`` (least squares) or a scalar; ``jac(x)`` returns ``(m, n)``.
    Returns an object with ``x`` ``(n,)``, ``fun`` (final objective), ``nfev``, ``success``
    and ``message``.
    """

    name: str

    def minimise(self, fun: Callable[[np.ndarray], Any], x0: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray, jac: Callable[[np.ndarray], np.ndarray] | None = None,
                 options: Mapping[str, Any] | None = None) -> Any:
        """Minimise ``fun`` from ``x0`` (n,) within ``[lower, upper]`` (see the class)."""


@runtime_checkable
class Effect(typing.Protocol):
    """A candidate unmodelled effect (``skinkit.effects``) for the sim-to-real gap diagnosis.

    ``kinds``: the model kinds the effect applies to (``"fe"``, ``"lumped"``).
    ``parameters()`` declares what the effect adds to a model, with units, admissible
    bounds and a typical magnitude as the value; ``null()`` gives the parameter values at
    which a model with the effect is exactly the model without it (name -> SI value).
    ``apply(model, p)`` returns a copy of a model description (a mapping, as read from a
    model file) with the effect added and its parameters set from ``p`` (name -> SI value);
    it raises :class:`skinkit.errors.EffectError` when the effect does not fit the model.

    In the description, an effect may bind a parameter to a model quantity the forward
    model differentiates (``model["bindings"]["<effect>.<parameter>"] = "<model parameter>"``,
    e.g. ``"viscoelastic.g1" -> "skin.g1"``), or write a field, load or instrument table
    whose parameters the forward model differentiates directly (see
    ``docs/guide/effects.md``); parameters it does neither for are differentiated by central
    differences.

    Optional, for the conformance kit (:mod:`skinkit.plugin.conformance.effects`) and the
    contract tests: ``touches``, a mapping model kind -> the top-level tables of a description
    ``apply`` may change, and ``once`` (default True): ``apply`` refuses a description it
    already edited.
    """

    name: str
    kinds: tuple[str, ...]

    def parameters(self) -> Sequence[Parameter]:
        """Declared parameters, the typical magnitude as value, with units and admissible bounds."""

    def null(self) -> Mapping[str, float]:
        """The parameter values (name -> SI) at which the effect changes nothing."""

    def apply(self, model: Mapping[str, Any], p: Mapping[str, Any]) -> Mapping[str, Any]:
        """A copy of the description ``model`` with the effect added at parameters ``p`` (name -> SI)."""


@runtime_checkable
class ForwardModel(typing.Protocol):
    """A model that predicts what a session measured (built by :func:`skinkit.forward.load`).

    ``parameters()``: every parameter of the model (law, pre-stretch, effect and lumped
    parameters) with units, bounds and the model file's values.
    ``predict(params, observations, sensitivities=False)``: a
    :class:`~skinkit.schemas.Prediction` with, for every protocol of ``observations``, the
    predicted values of every channel the model predicts, on exactly the observed times
    and points (the channel that drives the model is not predicted). ``sensitivities``:
    False, True (every parameter) or a list of parameter names; derivatives come in
    ``ChannelPrediction.d`` per SI unit of each parameter.

    Lifecycle: a model may hold resources between predictions (worker processes);
    ``close()`` releases them and may be called any number of times. A model is a context
    manager that closes itself on exit::

        with skinkit.forward.load("model.toml") as model:
            pred = model.predict(model.parameters(), observations)

    The forward models subclass this protocol and inherit ``close`` (nothing to release),
    ``__enter__`` and ``__exit__``; a model with resources overrides ``close``.
    """

    name: str
    kind: str

    def parameters(self) -> ParameterSet:
        """Every parameter of the model with units, bounds and the model file's values."""

    def predict(self, params: ParameterSet, observations: Any, sensitivities: Any = False) -> Any:
        """The predicted channels of every protocol of ``observations`` (with sensitivities on request)."""

    def close(self) -> None:
        """Release what the model holds between predictions; idempotent (nothing by default)."""
        return None

    def __enter__(self) -> ForwardModel:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


#: entry-point group -> interface class
GROUPS: dict[str, type] = {
    "skinkit.drivers": Driver,
    "skinkit.trackers": Tracker,
    "skinkit.profilers": Profiler,
    "skinkit.laws": Law,
    "skinkit.optimisers": Optimiser,
    "skinkit.effects": Effect,
}


def required_members(interface: type) -> list[str]:
    """Names a plugin must provide to satisfy ``interface`` (attributes and methods)."""
    names = set(getattr(interface, "__annotations__", {}))
    for name, value in vars(interface).items():
        if callable(value) and not name.startswith("_"):
            names.add(name)
    return sorted(names)


def missing_members(obj: Any, interface: type) -> list[str]:
    """Members of ``interface`` that ``obj`` (a class or an instance) lacks, or has but cannot
    call where the interface defines a method (reported as ``"name (not callable)"``)."""
    out = []
    for m in required_members(interface):
        if not hasattr(obj, m):
            out.append(m)
        elif callable(vars(interface).get(m)) and not callable(getattr(obj, m)):
            out.append(f"{m} (not callable)")
    return out


__all__ = [
    "GROUPS",
    "Driver",
    "Effect",
    "ForwardModel",
    "Law",
    "Optimiser",
    "ParameterSet",
    "Profiler",
    "Tracker",
    "missing_members",
    "required_members",
]
