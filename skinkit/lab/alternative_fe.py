"""Sessions of the alternative gap benchmark on the finite-element model: truths made apart from
the effect plugins.

The base response is the diagnosed model's own (the benchmark's quick finite-element preset: the
layered GOH + QLV forearm on its benchmark mesh, displacement-driven, one period of the four
default Table 12 protocols), solved once without any effect on the model's mesh — a
finite-element response cannot be written in a few lines of NumPy, so what is withheld here is
the *form* of the effect, not the solver. Each protocol starts with :data:`REST_S` at the zero
position (the robot settling before it moves), so that a reader estimates the sensors' noise
and its colour from the record, as a lab's record allows. Protocols follow each other on one
session clock with :data:`BETWEEN_S` between them (what the sensor's zero does in the pause is
part of the record).

Every form is put on the recorded tip force by NumPy (:mod:`skinkit.lab.alt_forms`,
:mod:`skinkit.lab.alt_noise`), on all three components with weights :data:`AXIS_WEIGHTS`:

* ``effect``: a zero drifting over the session clock and tared as each protocol starts (a
  two-time-constant warm-up, a thermal swing; the plugins' drift is linear, one exponential or a
  spline from each protocol's start), the force clock running slow (the plugin's lag is constant),
  a softening from one protocol to the next (constant within each protocol: exact for a uniform
  softening of every layer under an imposed displacement, where the displacement field is
  unchanged and every force scales). A zero drifting across protocols *without* taring (each
  protocol starting at the offset reached so far) is outside every installed drift's form
  (``force-warmup``'s "not covered"): the diagnosis names ``force-offset`` for it
  (``docs/guide/gap-benchmark.md``);
* ``null``: white, AR(1) φ 0.9 or spiky noise on the force;
* ``out-of-library``: mains pick-up, cable tugs.

**Magnitudes** are fixed and physical, chosen as the lumped truths' are (module
:mod:`skinkit.lab.alternative`): the model fitted to the noiseless truth leaves a χ² excess of
about 35 times the global χ² test's detection threshold at α = 0.05 (the benchmark records it per
case as ``visible_excess``).

The tracked points carry the tracker's white noise at its declared level (the lab's).
"""

from __future__ import annotations

import copy
import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from skinkit.lab import alt_forms as af
from skinkit.lab import alt_noise as an
from skinkit.lab.alternative import DRIFTING_ZERO, Form
from skinkit.schemas import Channel, Observations, ProtocolObservations, RobotRecord

#: the rest at the zero position before each protocol moves [s] (hundreds of samples at the record's rate)
REST_S = 3.0
#: the pause between protocols on the session clock [s]
BETWEEN_S = 10.0
#: the force clock's lag gained per second of a record (the clock-skew form) [s/s]
SKEW = 0.008
#: a form's size on the force's x, y, z components (z, the normal, the largest)
AXIS_WEIGHTS = np.array([0.6, 0.8, 1.0])
FAMILIES = ("effect", "null", "out-of-library")


def with_rest(spec: Mapping[str, Any]) -> dict[str, Any]:
    """``spec`` (a finite-element description with a ``[session]``) with :data:`REST_S` before
    every protocol."""
    out = copy.deepcopy(dict(spec))
    session = out.setdefault("session", {})
    params = session.setdefault("parameters", {})
    for name in session.get("protocols", []):
        params.setdefault(name, {})["rest"] = REST_S
    return out


_LABS: dict[str, Any] = {}


def _lab(spec: Mapping[str, Any]) -> Any:
    """The base truth of ``spec``, solved once per process on the model's mesh."""
    from skinkit.inverse.coverage import LabSessions

    key = json.dumps(spec, sort_keys=True, default=str)
    if key not in _LABS:
        _LABS.clear()
        _LABS[key] = LabSessions(spec, mesh="shared")
    return _LABS[key]


def _clock(lab: Any) -> list[float]:
    """Each protocol's start on the session clock [s]."""
    starts, t = [], 0.0
    for p in lab.truth.planned:
        starts.append(t)
        t += float(p.time_s[-1] - p.time_s[0]) + BETWEEN_S
    return starts


# a form: (parts, the truth's random stream, σ (3,) [N]) -> (recorded forces, what was drawn); a part
# is one protocol: {"t": (T,) session clock [s], "force": (T, 3) noiseless [N], "index": k}
Parts = list[dict[str, Any]]


def _each(core: Any) -> Any:
    """A builder: ``core(part) -> (T, 3)`` on every protocol, then white noise."""
    def build(parts: Parts, rng: np.random.Generator, sigma: np.ndarray) -> tuple[list[np.ndarray], dict]:
        return [core(p) + sigma * rng.standard_normal(p["force"].shape) for p in parts], {}
    return build


def _additive(series: Any, restart: bool = False) -> Any:
    """A builder adding ``series(t) (T,)`` [N] along :data:`AXIS_WEIGHTS`, t on the session clock
    (``restart``: t from the protocol's start, the transient restarted by each taring)."""
    def core(p: dict[str, Any]) -> np.ndarray:
        t = p["t"] - p["t"][0] * restart
        return p["force"] + series(t)[:, None] * AXIS_WEIGHTS
    return _each(core)


def _noise(draw: Any) -> Any:
    def build(parts: Parts, rng: np.random.Generator, sigma: np.ndarray) -> tuple[list[np.ndarray], dict]:
        return [p["force"] + np.stack([draw(rng, p["t"].size, s) for s in sigma], axis=1) for p in parts], {}
    return build


def _spiky(parts: Parts, rng: np.random.Generator, sigma: np.ndarray) -> tuple[list[np.ndarray], dict]:
    out, count = [], 0
    for p in parts:
        cols = []
        for s in sigma:
            sp = an.spikes(rng, p["t"].size, s, count=(1, 5))
            cols.append(an.white(rng, p["t"].size, s) + sp.series(p["t"].size))
            count += int(sp.index.size)
        out.append(p["force"] + np.stack(cols, axis=1))
    return out, {"spikes": count}


def _skewed(parts: Parts, rng: np.random.Generator, sigma: np.ndarray) -> tuple[list[np.ndarray], dict]:
    # the force clock slow: each record starts on a common trigger and its lag grows from 0 by
    # SKEW of its time (af.clock_skew, per component)
    out = []
    for p in parts:
        t = p["t"] - p["t"][0]
        f = np.stack([af.clock_skew(t, p["force"][:, j], SKEW * t[-1]) for j in range(3)], axis=1)
        out.append(f + sigma * rng.standard_normal(f.shape))
    return out, {}


def _tugged(parts: Parts, rng: np.random.Generator, sigma: np.ndarray) -> tuple[list[np.ndarray], dict]:
    out, centres = [], []
    for p in parts:
        tugs, c = af.cable_tugs(p["t"], rng, 0.013, 1, 1.0, margin=2.0)
        out.append(p["force"] + tugs[:, None] * AXIS_WEIGHTS + sigma * rng.standard_normal(p["force"].shape))
        centres += [round(float(x), 2) for x in c]
    return out, {"tugs_s": centres}


def _softened(s: float, pace: float | None) -> Any:
    """Protocol k's force scaled by 1 − s (1 − e^(−k/pace)) (``pace`` None: a step after the first)."""
    def factor(k: int) -> float:
        return 1.0 - (s * (k > 0) if pace is None else s * -np.expm1(-k / pace))
    return _each(lambda p: p["force"] * factor(p["index"]))


FORMS: tuple[Form, ...] = (
    Form("effect", "warmup-drift", "force-drift",
         "warm-up with two time constants restarted by each taring, 2.5 mN (1 − e^(−t/4 s)) + 4 mN "
         "(1 − e^(−t/60 s)), t from the protocol's start",
         _additive(lambda t: af.warmup_drift(t, (0.0025, 0.004), (4.0, 60.0)), restart=True),
         also=DRIFTING_ZERO),
    Form("effect", "log-settling", "force-drift",
         "a zero settling logarithmically after each taring (a bonded gauge's creep), 1.2 mN ln(1 + t/1 s)",
         _additive(lambda t: 0.0012 * np.log1p(t / 1.0), restart=True), also=DRIFTING_ZERO),
    Form("effect", "clock-skew", "channel-lag",
         "force clock running slow: each record's lag grows from 0 at its trigger by 8 ms per second",
         _skewed),
    Form("effect", "protocol-softening", "preconditioning",
         "protocol k's force scaled by 1 − 0.055 (1 − e^(−k/1.5)) (constant within a protocol)",
         _softened(0.055, 1.5)),
    Form("null", "white", None, "white Gaussian noise at σ", _noise(an.white)),
    Form("null", "ar1-0.9", None, "AR(1) noise, φ 0.9, marginal σ",
         _noise(lambda r, n, s: an.ar1(r, n, 0.9, s))),
    Form("null", "spikes", None, "white noise and 1-5 isolated spikes of 10-30 σ per component and protocol",
         _spiky),
    Form("out-of-library", "mains", None,
         "mains pick-up 3 mN at 49.8 Hz and its third harmonic",
         _additive(lambda t: af.mains_interference(t, 0.003))),
    Form("out-of-library", "cable-tug", None,
         "the sensor's cable tugged once per protocol: a ±13 mN raised-cosine bump of 1 s", _tugged),
)

#: installed effects for finite-element models with no truth here, and why
SKIPPED_EFFECTS = {
    "force-offset": "a constant offset is the simplest drifting zero; no NumPy form of it differs from the "
                    "plugin's",
    "viscoelastic": "the model already relaxes (its QLV term, g1 free); another relaxation form changes the "
                    "stress inside the tissue and needs a finite-element solve of its own",
    "robot-compliance": "a series spring changes the displacement the skin sees, so the field: it needs a "
                        "finite-element solve of its own",
}
_GEOMETRY = ("it changes the field, not the recorded force alone: a form of it written apart from the "
             "plugin needs a finite-element solve of its own")


def form(name: str) -> Form:
    """The form called ``name`` (:data:`FORMS`); KeyError naming the known ones otherwise."""
    for f in FORMS:
        if f.name == name:
            return f
    raise KeyError(f"no finite-element alternative truth form {name!r} "
                   f"(forms: {', '.join(f.name for f in FORMS)})")


def skipped_reason(effect: str) -> str:
    """Why an applicable effect has no truth form here."""
    return SKIPPED_EFFECTS.get(effect, _GEOMETRY)


def _rng(name: str, seed: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), sum(ord(c) * 31**i for i, c in enumerate(name)) % 2**31, 4244])


def truth(name: str, seed: int | None, spec: Mapping[str, Any]) -> dict[str, Any]:
    """Form ``name``'s forces per protocol on the base response of ``spec`` (the model's description
    at the truth, :func:`with_rest`): ``protocols`` (names), ``force`` [(T, 3)] [N] (model
    frame; ``seed`` None: noiseless, noise left out and any artefact kept), ``sigma`` (3,) [N],
    ``starts`` [s] on the session clock and what the draw holds (``info``)."""
    f = form(name)
    lab = _lab(spec)
    starts = _clock(lab)
    parts = [{"t": p.time_s - p.time_s[0] + s0, "index": k,
              "force": np.asarray(lab.truth.noiseless[p.protocol.name]["tip_force"], float)}
             for k, (p, s0) in enumerate(zip(lab.truth.planned, starts, strict=True))]
    sigma = np.asarray(lab.truth.sensors.sigma("tip_force"), float) * (seed is not None)
    forces, info = f.build(parts, _rng(name, 0 if seed is None else seed), sigma)
    return {"protocols": lab.protocols, "force": forces, "sigma": sigma, "starts": starts, "info": info}


def record(name: str, seed: int, k: int, spec: Mapping[str, Any]) -> RobotRecord:
    """Protocol ``k`` of form ``name``'s session with noise ``seed`` as a robot record (robot frame,
    z into the skin): the drive with the encoder's noise, the force as :func:`truth` makes it."""
    lab = _lab(spec)
    p = lab.truth.planned[k]
    tr = truth(name, seed, spec)
    u = np.asarray(lab.truth.noiseless[p.protocol.name]["tip_position"], float)
    rng = np.random.default_rng([int(seed), k, 7, 4244])
    u = u + lab.truth.sensors.sigma("tip_position") * rng.standard_normal(u.shape)
    flip = np.array([1.0, 1.0, -1.0])
    return RobotRecord(time_s=p.time_s, tip_position=u * flip, tip_force=tr["force"][k] * flip,
                       protocol=p.protocol)


def session(name: str, seed: int | None, spec: Mapping[str, Any]) -> Observations:
    """Form ``name``'s session with noise ``seed``, read as a lab's records are
    (:func:`skinkit.forward.observations.channels_from_record`: noise level, colour and spikes
    estimated from each record), with the tracked points of the lab's session ``seed``
    (``seed`` None: the noiseless session at the declared noise levels)."""
    from skinkit.forward.observations import channels_from_record

    lab = _lab(spec)
    if seed is None:
        return _noiseless(name, lab, spec)
    pts = lab(int(seed))
    out = {}
    for k, p in enumerate(lab.truth.planned):
        where = f"alternative truth {name}, {p.protocol.name}"
        chans = channels_from_record(record(name, seed, k, spec), where)
        if "points" in pts[p.protocol.name].channels:
            chans["points"] = pts[p.protocol.name].channels["points"]
        out[p.protocol.name] = ProtocolObservations(p.protocol, chans)
    return Observations(out, None, f"alternative finite-element truth {name}, seed {seed}")


def _noiseless(name: str, lab: Any, spec: Mapping[str, Any]) -> Observations:
    obs = lab.noiseless()
    tr = truth(name, None, spec)
    out = {}
    for k, p in enumerate(lab.truth.planned):
        chans = dict(obs[p.protocol.name].channels)
        f = chans["tip_force"]
        chans["tip_force"] = Channel("tip_force", f.time_s, tr["force"][k], noise=f.noise,
                                     noise_source=f.noise_source)
        out[p.protocol.name] = ProtocolObservations(p.protocol, chans)
    return Observations(out, None, f"alternative finite-element truth {name}, noiseless")


__all__ = ["AXIS_WEIGHTS", "BETWEEN_S", "FORMS", "REST_S", "SKEW", "SKIPPED_EFFECTS", "form", "record",
           "session", "skipped_reason", "truth", "with_rest"]
