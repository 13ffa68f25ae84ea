"""Robot-agnostic acquisition: the thesis's measurement protocols and the protocol runner.

``make_protocol(name, **params)`` builds a named protocol; ``programme_for(protocol)`` its
setpoints; ``run_protocol(driver, protocol, experiment)`` executes it through any driver and
streams the samples into the experiment store.

This package is also the stable API for authors of drivers (``skinkit.drivers``): everything in
``__all__`` is public and kept stable. A driver turns a measurement protocol
(:class:`skinkit.schemas.Protocol`) into setpoints with :func:`programme_for` (a
:class:`Programme`: mode, rate, ``(n, 3)`` setpoints), yields
:class:`skinkit.schemas.RobotRecord` blocks, and sets the ``FLAG_*`` bits per sample
(:data:`FLAG_NAMES` names them). An optional driver attribute ``wire_bits_per_sample`` (bits a
sample costs on the link, framing included) and ``line_rate_option`` (the ``connect`` option
that sets the link's rate in bit/s or baud) let ``skinkit bench robot`` state the link's
capacity.
"""

from skinkit.acquisition.library import ProtocolError, catalogue, make_protocol, names
from skinkit.acquisition.library import programme as programme_for
from skinkit.acquisition.programmes import Programme, direction, one_sided_sine, stochastic
from skinkit.acquisition.runner import RunSummary, run_protocol
from skinkit.schemas.robot import (
    FLAG_CAMERA_TRIGGER,
    FLAG_CONTACT,
    FLAG_ESTOP,
    FLAG_LIMIT,
    FLAG_NAMES,
    FLAG_SAMPLES_LOST,
    FLAG_SATURATED,
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
