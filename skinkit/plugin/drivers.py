"""The stable API for authors of robot drivers (``skinkit.drivers``) and of hosts that run
protocols on them.

Everything in ``__all__`` is public and kept stable; the engine modules it re-exports from
(:mod:`skinkit.acquisition`) may change. A driver turns a measurement protocol
(:class:`skinkit.schemas.Protocol`) into setpoints, yields :class:`skinkit.schemas.RobotRecord`
blocks and sets the ``FLAG_*`` bits per sample:

- :func:`programme_for` a protocol -> :class:`Programme` (mode, rate [Hz], ``(n, 3)``
  setpoints [m or N]); its building blocks :func:`direction`, :func:`one_sided_sine`,
  :func:`stochastic`;
- the per-sample flag bits :data:`FLAG_SATURATED`, :data:`FLAG_LIMIT`, :data:`FLAG_ESTOP`,
  :data:`FLAG_SAMPLES_LOST`, :data:`FLAG_CAMERA_TRIGGER`, :data:`FLAG_CONTACT`, and
  :data:`FLAG_NAMES` (bit -> name);
- for hosts: :func:`make_protocol`, :func:`catalogue`, :func:`names` (the protocol library),
  :func:`run_protocol` (a driver's records into an experiment file, returning a
  :class:`RunSummary`) and :class:`ProtocolError`.

Optional driver attributes: ``wire_bits_per_sample`` (bits a streamed sample costs on its
link, framing included) and ``line_rate_option`` (the ``connect`` option that sets the link's
rate [bit/s or baud]). A driver is checked with
:func:`skinkit.plugin.conformance.drivers.check_driver`.
"""

from __future__ import annotations

from skinkit.acquisition import (
    FLAG_CAMERA_TRIGGER,
    FLAG_CONTACT,
    FLAG_ESTOP,
    FLAG_LIMIT,
    FLAG_NAMES,
    FLAG_SAMPLES_LOST,
    FLAG_SATURATED,
    Programme,
    ProtocolError,
    RunSummary,
    catalogue,
    direction,
    make_protocol,
    names,
    one_sided_sine,
    programme_for,
    run_protocol,
    stochastic,
)

__all__ = [
    "FLAG_CAMERA_TRIGGER",
    "FLAG_CONTACT",
    "FLAG_ESTOP",
    "FLAG_LIMIT",
    "FLAG_NAMES",
    "FLAG_SAMPLES_LOST",
    "FLAG_SATURATED",
    "Programme",
    "ProtocolError",
    "RunSummary",
    "catalogue",
    "direction",
    "make_protocol",
    "names",
    "one_sided_sine",
    "programme_for",
    "run_protocol",
    "stochastic",
]
