"""Sessions of the alternative gap benchmark: truths made apart from the effect plugins.

The withheld-effect benchmark makes its truths with the very plugins the diagnosis tests, so it
shows consistency only. Here every truth is the lumped extension model's own response — an
exponential element F = a (exp(b u) − 1) and the force sensor's zero, driven by four cycles
of ramp (1 mm/s to 9 mm), 40 s hold and return (5 s rest first, 2 s between cycles, 100 Hz,
24,301 samples) — with a form from :mod:`skinkit.lab.alt_forms` put in by NumPy, and noise
from :mod:`skinkit.lab.alt_noise`. Three families:

* ``effect``: one effect the model lacks, in a form the candidates do not share; the right
  answer names that effect and nothing else;
* ``null``: the model's own response with white, AR(1) (φ 0.5 and 0.9, marginal σ the
  declared force noise) or spiky noise; the right answer names nothing;
* ``out-of-library``: an artefact no installed effect describes; the right answer names
  nothing and reports the residual as unexplained.

**Magnitudes** (:data:`FORMS`) are fixed and physical, chosen so that each truth is clearly
visible: the base model fitted to the noiseless truth leaves a χ² excess of about 30 times
(24 to 40) the global χ² test's detection threshold at α = 0.05, E ≈ 364 noise variances on this
record — about 1e4 noise variances, the withheld-effect benchmark's "moderate" magnitude (the
benchmark measures and records it per case as ``visible_excess``).

The declared force noise σ is the virtual lab's (:mod:`skinkit.lab.sensors`, about 3.9 mN);
the drive is exact; the force's y and z components (not predicted) carry white noise only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.lab import alt_forms as af
from skinkit.lab import alt_noise as an
from skinkit.lab.sensors import SensorModel
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations, RobotRecord

#: the truth's elastic element and force zero: the values of docs/models/extension_relaxation_lumped.toml
TRUE_A_N = 0.015
TRUE_B_PER_M = 320.0
TRUE_ZERO_N = -0.077
#: the protocol's name in the sessions
PROTOCOL = "extension_cycles"
FAMILIES = ("effect", "null", "out-of-library")


def force_sigma() -> float:
    """The declared noise of one force sample along x [N] (the virtual lab's Nano17)."""
    return float(SensorModel().sigma("tip_force")[0])


def programme() -> af.Programme:
    """The drive: 4 cycles to 9 mm at 1 mm/s, 40 s holds, 5 s rest first, 2 s between, 100 Hz."""
    return af.ramp_hold_return(peak_m=9e-3, speed_m_s=1e-3, hold_s=40.0, cycles=4, rest_s=5.0,
                               between_s=2.0, rate_hz=100.0)


# a form: (programme, the element's force (T,) [N], the truth's random stream, σ [N]) ->
# (recorded force along x (T,) [N] with the zero and noise, what was drawn for the record)
Builder = Callable[[af.Programme, np.ndarray, np.random.Generator, float], tuple[np.ndarray, dict[str, Any]]]


@dataclass(frozen=True)
class Form:
    """One kind of truth: ``family`` (:data:`FAMILIES`), ``name``, the ``effect`` a right answer
    names (None: nothing), what it is (``description``, with its magnitudes) and its builder."""

    family: str
    name: str
    effect: str | None
    description: str
    build: Builder = field(repr=False)
    also: tuple[str, ...] = ()

    @property
    def accepted(self) -> tuple[str, ...]:
        """The effects a right answer may name: ``effect`` and the ones that describe the same
        phenomenon in another shape (``also``: a drifting zero is a drift, a warm-up or a wander)."""
        return ((self.effect,) if self.effect else ()) + self.also


#: the effects that describe a force zero moving with time, each in its own shape
DRIFTING_ZERO = ("force-warmup", "force-wander")


def _white(core: Callable[[af.Programme, np.ndarray], np.ndarray]) -> Builder:
    """A builder: the noiseless force ``core(prog, fe)``, the zero and white noise."""
    def build(prog: af.Programme, fe: np.ndarray, rng: np.random.Generator, sigma: float
              ) -> tuple[np.ndarray, dict[str, Any]]:
        return core(prog, fe) + TRUE_ZERO_N + an.white(rng, fe.size, sigma), {}
    return build


def _noise(draw: Callable[[np.random.Generator, int, float], np.ndarray]) -> Builder:
    """A null builder: the model's own force, the zero and ``draw(rng, n, σ)``."""
    def build(prog: af.Programme, fe: np.ndarray, rng: np.random.Generator, sigma: float
              ) -> tuple[np.ndarray, dict[str, Any]]:
        return fe + TRUE_ZERO_N + draw(rng, fe.size, sigma), {}
    return build


def _spiky(prog: af.Programme, fe: np.ndarray, rng: np.random.Generator, sigma: float
           ) -> tuple[np.ndarray, dict[str, Any]]:
    sp = an.spikes(rng, fe.size, sigma)
    noise = an.white(rng, fe.size, sigma) + sp.series(fe.size)
    return fe + TRUE_ZERO_N + noise, {"spikes": int(sp.index.size)}


def _clipping(prog: af.Programme, fe: np.ndarray, rng: np.random.Generator, sigma: float
              ) -> tuple[np.ndarray, dict[str, Any]]:
    # the sensor saturates at 90 % of the peak force: the tops of the ramps and the early holds read flat
    upper = TRUE_ZERO_N + 0.9 * float(np.max(fe))
    rec = af.clipped(fe + TRUE_ZERO_N + an.white(rng, fe.size, sigma), upper)
    return rec, {"clipped_samples": int(np.sum(rec >= upper))}


def _tugged(prog: af.Programme, fe: np.ndarray, rng: np.random.Generator, sigma: float
            ) -> tuple[np.ndarray, dict[str, Any]]:
    tugs, centres = af.cable_tugs(prog.t, rng, 0.030, 6, 1.0)
    return fe + TRUE_ZERO_N + tugs + an.white(rng, fe.size, sigma), {"tugs_s": [round(float(c), 2)
                                                                              for c in centres]}


def _dt(prog: af.Programme) -> float:
    return prog.dt


FORMS: tuple[Form, ...] = (
    Form("effect", "prony-two-term", "viscoelastic",
         "two Prony terms, g 0.05 at τ 1 s and g 0.04 at τ 30 s (hereditary integral)",
         _white(lambda p, fe: af.hereditary(_dt(p), fe, af.prony_antiderivative((0.05, 0.04), (1.0, 30.0))))),
    Form("effect", "power-law", "viscoelastic",
         "power-law relaxation G(t) = 0.9 + 0.1 (1 + t/0.5 s)^(−0.4) (hereditary integral)",
         _white(lambda p, fe: af.hereditary(_dt(p), fe, af.power_law_antiderivative(0.9, 0.5, 0.4)))),
    Form("effect", "stretch-relaxing", "viscoelastic",
         "relaxing fraction growing with stretch, 0.08 (u/u_max)², τ 8 s",
         _white(lambda p, fe: af.stretch_dependent_relaxation(p, fe, 0.08, 8.0))),
    Form("effect", "cycle-softening", "preconditioning",
         "cycle k scaled by 1 − 0.04 (1 − e^(−k/1.5))",
         _white(lambda p, fe: af.cycle_count_softening(p, fe, 0.04, 1.5))),
    Form("effect", "step-softening", "preconditioning",
         "first cycle at full stiffness, later cycles scaled by 0.97",
         _white(lambda p, fe: af.step_softening(p, fe, 0.03))),
    Form("effect", "warmup-drift", "force-drift",
         "warm-up with two time constants, 5 mN (1 − e^(−t/20 s)) + 8 mN (1 − e^(−t/200 s))",
         _white(lambda p, fe: fe + af.warmup_drift(p.t, (0.005, 0.008), (20.0, 200.0))),
         also=DRIFTING_ZERO),
    Form("effect", "thermal-drift", "force-drift",
         "thermal swing 4 mN sin(2π t/150 s + 0.7)",
         _white(lambda p, fe: fe + af.thermal_drift(p.t, 0.004, 150.0, 0.7)), also=DRIFTING_ZERO),
    Form("effect", "clock-skew", "channel-lag",
         "force clock running slow: lag growing from 0 to 0.25 s over the record",
         _white(lambda p, fe: af.clock_skew(p.t, fe, 0.25))),
    Form("effect", "dahl-friction", "guide-friction",
         "Dahl friction in the robot's guide, ±5 mN with 0.1 mm presliding, held when the motion stops",
         _white(lambda p, fe: fe + af.dahl_friction(p.u, 0.005, 1e-4))),
    Form("null", "white", None, "white Gaussian noise at σ", _noise(an.white)),
    Form("null", "ar1-0.5", None, "AR(1) noise, φ 0.5, marginal σ",
         _noise(lambda r, n, s: an.ar1(r, n, 0.5, s))),
    Form("null", "ar1-0.9", None, "AR(1) noise, φ 0.9, marginal σ",
         _noise(lambda r, n, s: an.ar1(r, n, 0.9, s))),
    Form("null", "spikes", None, "white noise and 5-20 isolated spikes of 10-30 σ", _spiky),
    Form("out-of-library", "clipping", None, "the force sensor saturating at 90 % of the peak force",
         _clipping),
    Form("out-of-library", "mains", None,
         "mains pick-up 3.5 mN at 49.8 Hz and its third harmonic, sampled at 100 Hz",
         _white(lambda p, fe: fe + af.mains_interference(p.t, 0.0035))),
    Form("out-of-library", "cable-tug", None,
         "the sensor's cable tugged six times: ±30 mN raised-cosine bumps of 1 s at random times",
         _tugged),
)

#: installed effects for lumped models with no truth here, and why: no form of them is visible
#: on this model once its own parameters are fitted, so no truth could make them the answer
SKIPPED_EFFECTS = {
    "force-offset": "the model fits its own force zero: a constant offset in any form is absorbed by it, "
                    "so no truth can make force-offset the right answer",
    "robot-compliance": "driven by displacement and without relaxation, a series spring only reshapes the "
                        "element's force-stretch curve, which a and b take up (a spring c F (1 + κ|F|) "
                        "leaves at most about 6 detection thresholds for c 3-80 mm/N, κ up to 40 /N: "
                        "alt_forms.series_nonlinear_spring)",
}


def form(name: str) -> Form:
    """The form called ``name`` (:data:`FORMS`); KeyError naming the known ones otherwise."""
    for f in FORMS:
        if f.name == name:
            return f
    raise KeyError(f"no alternative truth form {name!r} (forms: {', '.join(f.name for f in FORMS)})")


def _rng(name: str, seed: int) -> np.random.Generator:
    # one stream per form and seed, independent of the order cases run in
    return np.random.default_rng([int(seed), sum(ord(c) * 31**i for i, c in enumerate(name)) % 2**31, 4243])


def truth(name: str, seed: int | None) -> dict[str, Any]:
    """Form ``name``'s record: ``t``, ``u`` ``(T,)``, ``force`` ``(T,)`` [N] recorded along x
    (``seed`` None: noiseless, white noise left out and any artefact kept), ``sigma`` [N] and
    what the draw holds (e.g. ``spikes``)."""
    f = form(name)
    prog = programme()
    fe = af.exponential_force(prog.u, TRUE_A_N, TRUE_B_PER_M)
    sigma = force_sigma()
    rng = _rng(name, 0 if seed is None else seed)
    force, info = f.build(prog, fe, rng, 0.0 if seed is None else sigma)
    return {"t": prog.t, "u": prog.u, "force": force, "sigma": sigma, "info": info}


def protocol() -> Protocol:
    """The session's protocol record (the drive's settings)."""
    return Protocol(PROTOCOL, kind="trajectory",
                    parameters={"peak": 9e-3, "speed": 1e-3, "hold": 40.0, "cycles": 4, "rest": 5.0,
                                "between": 2.0, "rate": 100.0},
                    units={"peak": "m", "speed": "m/s", "hold": "s", "cycles": "1", "rest": "s",
                           "between": "s", "rate": "Hz"},
                    description="extension: ramp 1 mm/s to 9 mm, hold 40 s, return; 4 cycles")


def record(name: str, seed: int) -> RobotRecord:
    """Form ``name``'s session with noise ``seed`` as a robot record a lab would bring (robot
    frame): tip position ``(T, 3)`` (x the drive) with the lab's encoder noise, tip force
    ``(T, 3)`` (x the truth's record, y and z white noise). Nothing about its noise is declared:
    whoever reads it estimates the noise from the record itself."""
    tr = truth(name, seed)
    sens = SensorModel()
    n = tr["t"].size
    pos = np.zeros((n, 3))
    pos[:, 0] = tr["u"]
    force = np.zeros((n, 3))
    force[:, 0] = tr["force"]
    rng = np.random.default_rng([int(seed), 7, 4243])
    force[:, 1:] = tr["sigma"] * rng.standard_normal((n, 2))
    pos = pos + sens.sigma("tip_position") * rng.standard_normal((n, 3))
    # robot frame: z into the skin (a reader flips z; x, the axis here, is unchanged)
    flip = np.array([1.0, 1.0, -1.0])
    return RobotRecord(time_s=tr["t"], tip_position=pos * flip, tip_force=force * flip, protocol=protocol())


def noiseless(name: str) -> Observations:
    """Form ``name``'s noiseless session at the lab's declared noise levels (nothing to estimate)."""
    tr = truth(name, None)
    sens = SensorModel()
    n = tr["t"].size
    pos = np.zeros((n, 3))
    pos[:, 0] = tr["u"]
    force = np.zeros((n, 3))
    force[:, 0] = tr["force"]
    chans = {"tip_position": Channel("tip_position", tr["t"], pos, noise=sens.sigma("tip_position"),
                                     noise_source="virtual lab (declared)"),
             "tip_force": Channel("tip_force", tr["t"], force, noise=sens.sigma("tip_force"),
                                  noise_source="virtual lab (declared)")}
    return Observations({PROTOCOL: ProtocolObservations(protocol(), chans)}, None,
                        f"alternative truth {name}, noiseless")
