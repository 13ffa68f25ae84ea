"""Small model descriptions and synthetic sessions the effects kit predicts with.

- :func:`lumped_model` the shipped ``extension_relaxation_lumped`` model (an exponential element
  along x, displacement in, force out, with a force-sensor bias) and :func:`lumped_session` one
  ramp-hold-return extension record for it (10 Hz, 40 s): a prediction costs milliseconds;
- :func:`fe_model` a layered disc with an isotropic elastic skin and the coarsest mesh (every
  built-in finite-element effect fits it) and :func:`fe_session` an oblique 0.1 Hz push under
  force control, with tracked surface points: a prediction costs about a second. Its laws
  (``neo-hookean-ni``, ``neo-hookean-enu``) are skinkit-plugins', which an effect of
  finite-element models needs installed anyway.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

#: per-sample noise [SI] of the synthetic channels (the robot's and the tracker's, roughly)
NOISE = {"tip_position": 1.7e-6, "tip_force": 1.7e-3, "points": 4e-6}


def lumped_model() -> dict[str, Any]:
    """The shipped lumped extension-relaxation description (a fresh copy)."""
    from skinkit.examples import example_model
    from skinkit.forward import read_description

    return read_description(example_model("extension_relaxation_lumped"))


def lumped_session() -> Observations:
    """One extension along x: ramp to 9.45 mm in 9.45 s, hold 20 s, return, rest (10 Hz)."""
    t = np.arange(0.0, 40.0001, 0.1)
    up = np.clip(t, 0.0, 9.45)
    down = np.clip(t - 29.45, 0.0, 9.45)
    x = (up - down) * 1e-3
    pos = np.zeros((t.size, 3))
    pos[:, 0] = x
    chans = {"tip_position": Channel("tip_position", t, pos, noise=NOISE["tip_position"]),
             "tip_force": Channel("tip_force", t, np.zeros((t.size, 3)), noise=NOISE["tip_force"])}
    proto = Protocol("in_plane_000")
    return Observations({proto.name: ProtocolObservations(proto, chans)}, None, "conformance testbed")


#: surface points of :func:`fe_session` [m]: two rings of four around the indenter
_POINTS = np.array([[r * np.cos(a), r * np.sin(a), 0.0] for r in (3e-3, 5e-3) for a in np.linspace(0, 6, 4)])


def fe_model() -> dict[str, Any]:
    """A 20 mm disc, skin (neo-Hookean, 1.5 mm, one element) over a subdermal layer (3.5 mm,
    two elements), fixed rim and bottom, a 4 mm indenter under force control."""
    return {
        "model": {"name": "conformance-disc"},
        "geometry": {"kind": "disc", "diameter": "20 mm", "indenter_diameter": "4 mm", "n_inner": 2,
                     "n_ring": 2},
        "layers": [
            {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "neo-hookean-ni",
             "parameters": {"mu": "15 kPa", "K": "500 kPa"}},
            {"name": "subdermal", "thickness": "3.5 mm", "elements": 2, "law": "neo-hookean-enu",
             "parameters": {"E": "10 kPa", "nu": 0.45}},
        ],
        "boundary": {"fixed": ["outer", "bottom"]},
        "indenter": {"mode": "force"},
        "drive": {"max_step": "1 s"},
        "solver": {"rtol": 1e-12},
    }


def fe_session() -> Observations:
    """An oblique push (20 mN peak, normal and in plane at once, 0.1 Hz, 10 s): every channel has
    something an effect can move."""
    t = np.arange(0, 10.0001, 0.02)
    s = 0.5 * (1 - np.cos(2 * np.pi * 0.1 * t))
    force = 0.02 * s[:, None] * np.array([0.4, 0.2, -1.0])
    tf = np.arange(0, 10.0001, 1.0)
    chans = {"tip_force": Channel("tip_force", t, force, noise=NOISE["tip_force"]),
             "tip_position": Channel("tip_position", t, 0 * force, noise=NOISE["tip_position"]),
             "points": Channel("points", tf, np.repeat(_POINTS[:, None], tf.size, 1), noise=NOISE["points"],
                               reference=_POINTS)}
    proto = Protocol("oblique")
    return Observations({proto.name: ProtocolObservations(proto, chans)}, None, "conformance testbed")


__all__ = ["NOISE", "fe_model", "fe_session", "lumped_model", "lumped_session"]
