"""Robot-agnostic acquisition: the thesis's measurement protocols and the protocol runner.

``make_protocol(name, **params)`` builds a named protocol; ``programme_for(protocol)`` its
setpoints; ``run_protocol(driver, protocol, experiment)`` executes it through any driver and
streams the samples into the experiment store.
"""

from skinkit.acquisition.library import ProtocolError, catalogue, make_protocol, names
from skinkit.acquisition.library import programme as programme_for
from skinkit.acquisition.programmes import Programme, direction, one_sided_sine, stochastic
from skinkit.acquisition.runner import RunSummary, run_protocol

__all__ = [
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
