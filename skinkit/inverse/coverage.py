"""Coverage of the reported intervals: is the truth inside ``estimate ± z·se`` as often as claimed?

:func:`coverage` fits many virtual sessions of one known truth (one per seed) with
:func:`skinkit.inverse.fit` and counts, per parameter and overall, the parameter-seed pairs with
``|estimate − truth| ≤ z · se`` (z = 1.96 at the 95 % level; ``se`` the fit's standard error,
``FitResult.se``). If the intervals are honest the fraction is the level; too few
inside means hidden uncertainty (intervals too narrow, or a bias), too many means inflated
intervals. The count expected for exact coverage is binomial (n pairs, p = level); its central
95 % range is reported so a reader can judge a measured count. Pairs within one seed share that
seed's noise (their estimates are correlated through the covariance), so the overall count is
more dispersed than the binomial; the per-parameter counts (one pair per seed) are independent.

:class:`LabSessions` makes the virtual sessions: the virtual lab's truth run
(:func:`skinkit.lab.session.simulate`: the library protocols' programmes, the lab's time bases,
tracked points and camera frames) solved **once**, then for each seed Gaussian noise at exactly
the declared levels of the lab's instruments (:class:`skinkit.lab.sensors.SensorModel`) added to
every *predicted* channel, with those same levels declared to the fit. Why not the session file
the lab writes: its recorded channels also carry what the objective's noise model does not —
a tare offset per channel (constant over a protocol, σ/10: over ~10⁴ samples it moves the
estimate as much as the white noise does), the drive's own sensor noise (below), and noise
levels estimated back from rest segments (about 10 % sampling error in σ from ~100 samples).
Those are questions of the model's structure and of the noise estimator, not of the interval
at the optimum, which is what coverage measures.

**The drive.** The objective treats the recorded drive as exact: a model driven by a channel
predicts the others, and only their noise enters z. A session whose drive carries sensor
noise is an errors-in-variables problem: the noise enters the predicted channel through the
model (a force drive through the skin's compliance: 3.85 mN of force noise, averaged over a
0.5 s solver step, still moves the predicted tip by several µm against 1 µm of position
noise), correlated over a solver step and not counted in the Jacobian's covariance — the
estimates are biased towards a softer drive response and the intervals are too narrow.
``skinkit/bench/fit.py`` does that on purpose (a benchmark of cost, not of coverage). Here the
drive is the exact programme by default (``drive_noise=False``); ``drive_noise=True`` adds the
drive sensor's noise to measure that effect.

**Tracked points** follow the session reader's convention by default (``reference="measured"``):
frame 0 is measured like every frame, is the points' reference, and the objective whitens the
shared reference noise along frames. ``reference="exact"`` gives the fit the true reference.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError
from skinkit.schemas import Channel, Observations, ProtocolObservations

#: two-sided normal quantiles of the levels one asks for most
_Z = {0.90: 1.6448536269514722, 0.95: 1.959963984540054, 0.99: 2.5758293035489004}

CORRELATION_NOTE = ("pairs within one seed share that seed's noise, so the overall count is more "
                    "dispersed than the binomial range (which assumes independent pairs); the "
                    "per-parameter counts, one pair per seed, are independent across seeds")


class CoverageError(SkinkitError):
    """A coverage study that cannot run: no seed, an unknown parameter, a level outside (0, 1)."""


def z_of_level(level: float) -> float:
    """Two-sided standard-normal quantile of ``level`` (0.95 -> 1.96)."""
    if not 0 < level < 1:
        raise CoverageError(f"level must be in (0, 1), got {level!r}")
    for k, v in _Z.items():
        if abs(level - k) < 1e-12:
            return v
    from scipy.stats import norm

    return float(norm.ppf(0.5 + level / 2))


def expected_range(pairs: int, level: float = 0.95, mass: float = 0.95) -> tuple[int, int]:
    """Central ``mass`` range ``(lo, hi)`` of the inside count of ``pairs`` independent pairs
    under exact coverage (binomial(pairs, level))."""
    from scipy.stats import binom

    if pairs <= 0:
        return 0, 0
    lo, hi = binom.interval(mass, pairs, level)
    return int(lo), int(hi)


def outside_band_probability(pairs: int, level: float = 0.95, band: tuple[float, float] = (0.90, 0.99)
                             ) -> float:
    """Probability that the inside fraction of ``pairs`` independent pairs falls outside
    ``band`` when the coverage is exactly ``level`` (binomial)."""
    from scipy.stats import binom

    lo = math.ceil(band[0] * pairs - 1e-9)        # smallest count inside the band
    hi = math.floor(band[1] * pairs + 1e-9)       # largest count inside the band
    return float(binom.cdf(lo - 1, pairs, level) + binom.sf(hi, pairs, level))


# -- virtual sessions ------------------------------------------------------------------------------
class LabSessions:
    """Virtual sessions of one truth: the lab's truth run once, fresh noise per seed.

    ``spec``: a model description (FE or lumped) at the true parameters; ``protocols``: library
    names (default: the description's ``[session] protocols``, else the lab's default);
    ``reference``: ``"measured"`` or ``"exact"`` (module docstring); ``drive_noise``: add the
    drive sensor's noise to the drive (an errors-in-variables session; default False);
    ``noise_scale``: the lab's ``--noise-scale``; ``mesh``: a finite-element truth on a mesh of
    its own, ``mesh_factor`` times finer (``"own"``), the limit of three of its own, the finest
    ``mesh_factor`` times the model's counts (``"extrapolated"``), or the model's (``"shared"``:
    :func:`skinkit.lab.session.simulate`). Calling the object with a seed returns that
    seed's :class:`~skinkit.schemas.Observations`; :attr:`model_spec` is the description with
    the indenter mode the truth ran in (the model to fit has the truth's structure).
    """

    def __init__(self, spec: Mapping[str, Any], protocols: Sequence[str] | None = None,
                 reference: str = "measured", drive_noise: bool = False, noise_scale: float = 1.0,
                 workers: int | None = 1, mesh: str = "own", mesh_factor: int | None = None) -> None:
        from skinkit.forward import model_kind
        from skinkit.lab.session import simulate, top_surface

        if reference not in ("measured", "exact"):
            raise CoverageError(f"reference must be 'measured' or 'exact', got {reference!r}")
        self.spec = copy.deepcopy(dict(spec))
        self.kind = model_kind(self.spec)
        self.reference = reference
        self.drive_noise = drive_noise
        t0 = time.perf_counter()
        self.truth = simulate(self.spec, seed=0, protocols=protocols, noise_scale=noise_scale,
                              workers=workers, mesh=mesh, mesh_factor=mesh_factor)
        self.truth_wall_s = time.perf_counter() - t0
        drives = {p.drive for p in self.truth.planned}
        self.model_spec = copy.deepcopy(self.spec)
        if self.kind == "fe":
            if len(drives) != 1:
                raise CoverageError("the protocols mix position and force programmes; a model to fit has one "
                                    "indenter mode: choose protocols of one kind")
            self.model_spec.setdefault("indenter", {})["mode"] = \
                "displacement" if drives == {"tip_position"} else "force"
        surface = top_surface(self.spec, self.kind)
        self._ref = surface.track_reference() if (self.kind == "fe" and surface.has_mesh) else None
        if surface.curved:
            raise CoverageError("the truth fits its top to a profile ([surface] fit): set [surface] fit = "
                                "false so that truth and model share the flat surface exactly")

    @property
    def protocols(self) -> list[str]:
        """Protocol names, in session order."""
        return [p.protocol.name for p in self.truth.planned]

    def noiseless(self) -> Observations:
        """The noiseless truth as observations at the declared noise levels, the points' reference
        as the sessions have it: with a measured reference (the default) the noiseless frame 0 is
        the reference frame, so that an effect's signature is the one a session shows (whitened
        along frames, a distortion of the tracker seen in the reference too)."""
        sensors = self.truth.sensors
        measured = self.reference == "measured"
        out = {}
        for p in self.truth.planned:
            true = self.truth.noiseless[p.protocol.name]
            chans = {c: Channel(c, p.time_s, np.asarray(true[c], float), noise=sensors.sigma(c),
                                noise_source="virtual lab (declared)") for c in ("tip_position", "tip_force")}
            if "points" in true and self._ref is not None:
                v = np.asarray(true["points"], float)
                r0, f0 = (v[:, 0].copy(), 0) if measured else (self._ref.copy(), None)
                chans["points"] = Channel("points", p.frames, v, noise=sensors.sigma("points"),
                                          noise_source="tracker", reference=r0, reference_frame=f0)
            out[p.protocol.name] = ProtocolObservations(p.protocol, chans)
        return Observations(out, None, "virtual lab, noiseless")

    def __call__(self, seed: int) -> Observations:
        """The session of ``seed``: noiseless truth plus Gaussian noise at the declared levels."""
        sensors = self.truth.sensors
        out: dict[str, ProtocolObservations] = {}
        for i, p in enumerate(self.truth.planned):
            true = self.truth.noiseless[p.protocol.name]
            chans: dict[str, Channel] = {}
            # one stream per protocol and channel: the drive's noise (drive_noise) leaves the others' alone
            rngs = [np.random.default_rng([int(seed), i, k, 7919]) for k in range(3)]
            for k, c in enumerate(("tip_position", "tip_force")):
                sig = sensors.sigma(c)
                v = np.asarray(true[c], dtype=float)
                if c != p.drive or self.drive_noise:
                    v = v + sig * rngs[k].standard_normal(v.shape)
                chans[c] = Channel(c, p.time_s, v, noise=sig, noise_source="virtual lab (declared)")
            if "points" in true and self._ref is not None:
                sig = sensors.sigma("points")
                pts = np.asarray(true["points"], dtype=float)
                v = pts + sig * rngs[2].standard_normal(pts.shape)
                if self.reference == "measured":
                    chans["points"] = Channel("points", p.frames, v, noise=sig, noise_source="tracker",
                                              reference=v[:, 0].copy(), reference_frame=0)
                else:
                    chans["points"] = Channel("points", p.frames, v, noise=sig, noise_source="tracker",
                                              reference=self._ref.copy())
            out[p.protocol.name] = ProtocolObservations(p.protocol, chans)
        return Observations(out, None, f"virtual lab, seed {seed}")


# -- starts ----------------------------------------------------------------------------------------
def perturbed_start(model: Any, free: Sequence[str], spread: float = 0.2
                    ) -> Callable[[int], dict[str, float]]:
    """A start per seed: each free parameter's true value times exp(spread · N(0, 1)) (a
    relative perturbation of about ``spread``), or plus ``spread`` of its bounded range when
    its value is 0; kept strictly inside the bounds."""
    params = model.parameters()

    def start(seed: int) -> dict[str, float]:
        rng = np.random.default_rng([int(seed), 104729])
        out = {}
        for n in free:
            p = params.param(n)
            if p.value != 0:
                v = p.value * math.exp(spread * rng.standard_normal())
            else:
                width = (p.upper - p.lower) if math.isfinite(p.upper - p.lower) else 1.0
                v = p.value + spread * width * rng.standard_normal()
            pad = 1e-6 * (abs(p.value) + 1e-300)
            lo = p.lower + 1e-6 * abs(p.lower) + pad if math.isfinite(p.lower) else -math.inf
            hi = p.upper - 1e-6 * abs(p.upper) - pad if math.isfinite(p.upper) else math.inf
            out[n] = float(min(max(v, lo), hi))
        return out

    return start


# -- the study -------------------------------------------------------------------------------------
Progress = Callable[[int, int, dict[str, Any]], None]
Start = str | Mapping[str, float] | Callable[[int], Mapping[str, float]]


def coverage(model: Any, make_observations: Callable[[int], Observations], free: Sequence[str],
             seeds: Sequence[int] | int, start: Start = "truth", level: float = 0.95,
             truth: Mapping[str, float] | None = None,
             progress: Progress | None = None, **fit_options: Any) -> dict[str, Any]:
    """Fit the session of every seed and count how often the truth lies in the reported interval.

    ``model``: the forward model to fit, built at the true parameters (``truth`` overrides
    them: name -> SI value); ``make_observations(seed)``: that seed's session; ``free``: the
    parameters fitted; ``seeds``: the seeds, or a count (0..N-1); ``start``: ``"truth"`` (each
    fit starts at the truth: the question is the interval at the optimum), a mapping, or a
    callable ``start(seed)`` (e.g. :func:`perturbed_start`); ``level``: the interval's level
    (z = 1.96 at 0.95); ``progress(i, n, record)`` after each seed; ``fit_options`` go to
    :func:`skinkit.inverse.fit`.

    Returns a JSON-ready dict: ``coverage`` (inside/pairs), ``pairs``, ``inside``,
    ``expected_range`` (central 95 % of the inside count under exact coverage, independent
    pairs), ``expected_fraction``, ``per_parameter`` (the same per parameter, with the mean
    and RMS of z = (estimate − truth)/se: ≈ 0 and ≈ 1 when estimate and interval are honest),
    ``per_seed`` (estimates, se, z, inside, χ²/dof, evaluations, solves, wall time, converged,
    or the error of a fit that failed — its pairs count as outside), ``chi2_per_dof_mean``,
    ``wall_s``, ``note`` (the correlation of pairs within a seed).
    """
    from skinkit.inverse.fit import fit

    free = list(free)
    if not free:
        raise CoverageError("no free parameter")
    seeds = list(range(seeds)) if isinstance(seeds, (int, np.integer)) else [int(s) for s in seeds]
    if not seeds:
        raise CoverageError("no seed")
    params = model.parameters()
    missing = sorted(set(free) - set(params.names))
    if missing:
        raise CoverageError(f"the model has no parameter(s) {missing}")
    zq = z_of_level(level)
    true = {n: float(params[n]) for n in free}
    if truth:
        true.update({n: float(v) for n, v in truth.items() if n in true})
    records: list[dict[str, Any]] = []
    t_all = time.perf_counter()
    for i, seed in enumerate(seeds):
        obs = make_observations(seed)
        if callable(start):
            s0 = dict(start(seed))
        elif isinstance(start, Mapping):
            s0 = dict(start)
        elif start == "truth":
            s0 = dict(true)
        else:
            raise CoverageError(f"start must be 'truth', a mapping or a callable, got {start!r}")
        t0 = time.perf_counter()
        try:
            r = fit(model, obs, free, start=s0, **fit_options)
        except SkinkitError as exc:
            rec = {"seed": seed, "start": s0, "error": str(exc), "wall_s": time.perf_counter() - t0,
                   "inside": dict.fromkeys(free, False)}
        else:
            est = {n: float(r.parameters[n]) for n in free}
            se = {n: float(r.se[n]) for n in free}
            z = {n: (est[n] - true[n]) / se[n] if se[n] > 0 else math.copysign(math.inf, est[n] - true[n])
                 for n in free}
            rec = {"seed": seed, "start": s0, "estimates": est, "se": se, "z": z,
                   "inside": {n: bool(abs(est[n] - true[n]) <= zq * se[n]) for n in free},
                   "chi2_per_dof": float(r.chi2_per_dof),
                   "inflation": float(r.identifiability.get("inflation", 1)),
                   "evaluations": len(r.extra.get("history", [])), "n_forward": int(r.n_forward),
                   "n_sensitivity": int(r.n_sensitivity), "converged": bool(r.converged),
                   "message": r.message, "wall_s": time.perf_counter() - t0}
        records.append(rec)
        if progress is not None:
            progress(i + 1, len(seeds), rec)
    return _summary(records, free, true, level, zq, seeds, time.perf_counter() - t_all)


def _summary(records: list[dict[str, Any]], free: list[str], true: dict[str, float], level: float, zq: float,
             seeds: list[int], wall: float) -> dict[str, Any]:
    per: dict[str, Any] = {}
    for n in free:
        inside = sum(r["inside"][n] for r in records)
        zs = np.array([r["z"][n] for r in records if "z" in r], float)
        fin = zs[np.isfinite(zs)]
        per[n] = {"truth": true[n], "pairs": len(records), "inside": int(inside),
                  "coverage": inside / len(records),
                  "expected_range": list(expected_range(len(records), level)),
                  "mean_z": float(fin.mean()) if fin.size else None,
                  "rms_z": float(np.sqrt(np.mean(fin**2))) if fin.size else None,
                  "max_abs_z": float(np.abs(fin).max()) if fin.size else None,
                  "infinite_se": int(sum(1 for r in records if "se" in r and not math.isfinite(r["se"][n])))}
    pairs = len(records) * len(free)
    inside = sum(per[n]["inside"] for n in free)
    ok = [r for r in records if "error" not in r]
    lo, hi = expected_range(pairs, level)
    return {"level": level, "z": zq, "free": free, "truth": true, "seeds": seeds,
            "pairs": pairs, "inside": int(inside), "coverage": inside / pairs,
            "expected_range": [lo, hi], "expected_fraction": [lo / pairs, hi / pairs],
            "per_parameter": per, "per_seed": records, "failed": len(records) - len(ok),
            "chi2_per_dof_mean": float(np.mean([r["chi2_per_dof"] for r in ok])) if ok else None,
            "evaluations_mean": float(np.mean([r["evaluations"] for r in ok])) if ok else None,
            "fit_wall_s_mean": float(np.mean([r["wall_s"] for r in records])),
            "wall_s": wall, "note": CORRELATION_NOTE}


__all__ = ["CORRELATION_NOTE", "CoverageError", "LabSessions", "coverage", "expected_range",
           "outside_band_probability", "perturbed_start", "z_of_level"]
