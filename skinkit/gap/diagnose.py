"""The sim-to-real gap diagnosis of a calibrated model: where, which effect, how far.

:func:`diagnose` fits the model's free parameters to the session (exactly as ``skinkit fit``:
held-out protocols stay out of the fit), then in rounds:

1. **where** (:func:`skinkit.gap.where.locate`): the noise-normalised residual split by protocol,
   channel, phase, region and frequency, each cell tested against the noise;
2. **which** (:mod:`skinkit.gap.score`): a score test of every installed effect that applies
   to the model, at its null, from one prediction with sensitivities; the top candidates
   (``candidates``, default 3) whose test survives the Bonferroni correction are refitted with
   the effect added (its parameters free, started a linearised step from the null) and compared
   by AIC and held-out error (a candidate that declares a region is first scanned over the tracked
   points and tested and refitted at its best region: :mod:`skinkit.gap.scan_step`). An effect
   is **added** to the model only when all of these hold:

   * the gap is significant: the residual's family (step 1: the whole residual and every cell,
     Holm) or the score tests' family (the best candidate's p·K) rejects, each at α/2, so that
     on a session the model describes "significant gap" is said in at most α of sessions
     (the two families at α each would allow 2α; measured 5 of 60 null sessions so);
   * its score test survives the correction over the K effects tested (p·K < α);
   * its refit lowers the AIC by more than :data:`AIC_MARGIN` (10: Burnham & Anderson's
     "essentially no support" for the worse model; for one added parameter under the null the
     likelihood-ratio statistic would have to exceed 12, probability 5e-4, so noise alone
     names an effect in fewer than 1 in 400 sessions per candidate);
   * it does not worsen the held-out χ² by more than 2 per added parameter (under the null a
     useless parameter costs about 1 out of sample: the optimism of a fit).

   Of the candidates that qualify, one whose effect explained at least ``min_share`` of the
   first model's excess on its own comes first, then the lowest AIC; the model is augmented
   with it at its fitted values and the next round looks for another (``max_effects``). A
   repeatable effect in the model offers one more instance as a candidate of its own. Whether
   an added effect is a **cause** or a **minor** contribution, what remains unexplained, and the
   warnings are :mod:`skinkit.gap.verdict`'s.
3. **how far**: χ² before and after, overall and per cell, on fitted and held-out protocols;
   shrinkage = the fraction of the excess residual (χ² − dof) removed; the effect's identified
   magnitude with its standard error (from the refit's covariance).

Non-separable pairs (:func:`skinkit.gap.score.separability`) are reported with the library
protocol that would separate them best (:func:`skinkit.gap.score.separating_protocol`).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError
from skinkit.forward.stages import stage
from skinkit.gap.candidates import (
    AIC_MARGIN,
    best_qualifying,
    candidate_record,
    fraction,
    qualifies,
    refit_order,
    screened,
)
from skinkit.gap.checks import GapError, check_channels, check_effects
from skinkit.gap.mesh_check import discretisation, mesh_only
from skinkit.gap.report_files import write_report
from skinkit.gap.scan_step import RoundScan, ScanOptions, check_regions, rival_refit, scan_round
from skinkit.gap.score import (
    ScoreTest,
    Sensitivities,
    collect,
    corrected,
    directed_p,
    effect_of,
    effect_table,
    separability,
    separating_protocol,
    with_effects,
)
from skinkit.gap.sentences import messages, num
from skinkit.gap.series import diagnosis_series
from skinkit.gap.verdict import (
    MIN_SHARE,
    SMALL_REMAINDER,
    assign_roles,
    fit_warnings,
    noise_factor,
    noise_summary,
    record_warnings,
    remaining,
)
from skinkit.inverse.discretisation import has_mesh
from skinkit.schemas import EffectScore, FitResult, GapReport, Observations, Prediction

#: a refit starts at most this many typical magnitudes from the null
MAX_START = 2.0


# ---------------------------------------------------------------------------------- helpers
def _chi2(observations: Observations, prediction: Prediction, protocols: Sequence[str]) -> tuple[float, int]:
    """``(Σz², samples)`` of ``prediction`` over ``protocols`` (the fit's residual)."""
    from skinkit.inverse.objective import Objective

    keep = [p for p in protocols if p in prediction.protocols]
    if not keep:
        return 0.0, 0
    pred = Prediction({p: prediction.protocols[p] for p in keep}, prediction.methods, prediction.inputs)
    res = Objective(None, observations.select(keep), [], "noise").residual(pred, jacobian=False)
    return float(res.z @ res.z), int(res.z.size)


def _predict_all(model: Any, params: Any, observations: Observations) -> Prediction:
    return model.predict(params, observations, sensitivities=False)


def _merge(a: Prediction, b: Prediction | None) -> Prediction:
    if b is None:
        return a
    return Prediction({**a.protocols, **b.protocols}, {**a.methods, **b.methods}, {**a.inputs, **b.inputs},
                      dict(a.info))


def _values(result: FitResult) -> dict[str, float]:
    return {p.name: float(p.value) for p in result.parameters}


def _points(observations: Observations) -> dict[str, list[list[float]]]:
    out = {}
    for po in observations:
        for ch in po.channels.values():
            if ch.is_points and ch.reference is not None:
                out[po.name] = np.asarray(ch.reference)[:, :2].tolist()
    return out


def _cells(loc: Any) -> list[dict[str, Any]]:
    keys = ("axis", "label", "share", "chi2_per_dof", "p_value", "significant", "chi2", "dof", "n",
            "partition")
    return [{k: c.to_dict()[k] for k in keys if k in c.to_dict()} for c in loc.cells]


def _gap_dict(loc: Any) -> dict[str, Any]:
    d = loc.to_dict()
    d["cells"] = _cells(loc)
    d["ranked"] = [{"axis": c.axis, "label": c.label, "share": c.share} for c in loc.ranked()]
    return d


def _state(model: Any, result: FitResult, observations: Observations, held: Observations
           ) -> dict[str, Any]:
    """A calibrated state: its full prediction (fitted and held-out protocols), χ² and dof."""
    pred = _predict_all(model, result.parameters, observations)
    fitted = observations.fitted().names
    c_fit, n_fit = _chi2(observations, pred, fitted)
    c_ho, n_ho = _chi2(observations, pred, held.names)
    k = len(result.parameters.free_names)
    return {"prediction": pred, "chi2": c_fit, "n": n_fit, "k": k, "dof": n_fit - k,
            "held_chi2": c_ho, "held_n": n_ho, "result": result}


# -------------------------------------------------------------------------------- the rounds
def _refit(spec: Mapping[str, Any], effects_in: list[dict[str, Any]], observations: Observations,
           held: Observations, values: Mapping[str, float], theta: Sequence[str], test: ScoreTest,
           sens: Sensitivities, *, load: Callable[..., Any], say: Callable[[str], None],
           max_iterations: int = 50, form: tuple[str, Mapping[str, float]] | None = None) -> dict[str, Any]:
    """The model with ``test.effect`` added, refitted: its state, the added free parameters.
    ``form``: the form to refit it in and that form's start values (a region effect refitted as
    an ellipse from its shape scan, :mod:`skinkit.gap.shape_scan`), all of which are freed."""
    from skinkit.inverse import fit
    from skinkit.inverse.objective import Objective

    cols = sens.columns[test.effect]
    table = effect_table(test.effect)
    if form is not None:
        table["form"] = form[0]
        values = {**values, **form[1]}
    model = load(with_effects(spec, effects_in + [table]))
    try:
        ps = model.parameters()
        ps = ps.with_values({k: v for k, v in values.items() if k in ps.names})
        start = {}
        for n in test.tested:
            lo, hi = cols.bounds[n]
            span = MAX_START * (abs(cols.typical[n] - cols.null[n]) or abs(cols.typical[n]) or 1.0)
            v = cols.null[n] + float(np.clip(test.step.get(n, 0.0), -span, span))
            start[n] = float(np.clip(v, lo + 1e-9 * (hi - lo if math.isfinite(hi - lo) else 1), hi))
        ps = ps.with_values(start)
        added = list(test.tested)
        if form is not None:
            added += [n for n in form[1] if n not in added]
        elif cols.held:
            # parameters without a signature at the null: free those the switched-on effect shows
            held_names = list(cols.held)
            res, _ = Objective(model, observations.fitted(), held_names, "noise").evaluate(ps)
            for i, n in enumerate(held_names):
                size = abs(cols.typical[n] - cols.null[n]) or abs(cols.typical[n]) or 1.0
                if float(np.linalg.norm(res.J[:, i])) * size > 1e-3:
                    added.append(n)
        free = list(theta) + added
        say(f"refit with {test.effect}: free {', '.join(added)}")
        r = fit(model, observations, free, start={n: ps[n] for n in free}, max_iterations=max_iterations)
        state = _state(model, r, observations, held)
    finally:
        model.close()
    state["added"] = added
    state["table"] = {**effect_table(test.effect, _values(r)), **({"form": form[0]} if form else {})}
    # every free parameter: an earlier effect's, refitted with this one, may reach a bound now
    state["warnings"] = fit_warnings(r, f"the refit with {test.effect}", free)
    return state


@dataclass
class _Run:
    """What the rounds share: the inputs (fixed) and the diagnosis so far (updated by each round)."""

    spec: Mapping[str, Any]
    base: Any
    observations: Observations
    held: Observations
    present: list[str]
    loader: Callable[..., Any]
    say: Callable[[str], None]
    alpha: float
    candidates: int
    max_effects: int
    error_estimate: bool
    state0: dict[str, Any]
    current: dict[str, Any]
    theta_r: list[str]
    remaining: list[str]
    n_forward: int
    rounds: list[dict[str, Any]] = field(default_factory=list)
    named: list[str] = field(default_factory=list)
    tables: list[dict[str, Any]] = field(default_factory=list)
    separation: list[dict[str, Any]] = field(default_factory=list)
    gap0: dict[str, Any] = field(default_factory=dict)
    first_candidates: list[EffectScore] = field(default_factory=list)
    loc0: Any = None
    disc: dict[str, Any] | None = None
    min_share: float = MIN_SHARE
    additions: list[dict[str, Any]] = field(default_factory=list)
    warnings: list[dict[str, Any]] = field(default_factory=list)
    undermined: dict[str, str] = field(default_factory=dict)
    winners: list[EffectScore] = field(default_factory=list)
    first_scores: tuple[Any, Any] | None = None
    max_iterations: int = 50
    final: FitResult | None = None   # the final model refitted with its own model error
    regions: Any = None              # the model geometry's regions of the tracked surface (where.locate)
    scan: ScanOptions | None = None  # region scans (skinkit.gap.scan_step): options, results, best regions
    scans: list[dict[str, Any]] = field(default_factory=list)
    held_regions: dict[str, float] = field(default_factory=dict)
    held_forms: dict[str, tuple[str, dict[str, float]]] = field(default_factory=dict)

    @property
    def final_fit(self) -> FitResult:
        """The final model's fit to report: refitted with its own model error when it was."""
        return self.final or self.current["result"]


def diagnose(model: str | os.PathLike[str] | Mapping[str, Any],
             observations: Observations | str | os.PathLike[str], *,
             effects: Sequence[str] | None = None, holdout: Sequence[str] = (),
             free: Sequence[str] | None = None, max_effects: int = 2, candidates: int = 3,
             alpha: float = 0.05, workers: int | None = None, until: float | None = None,
             progress: Callable[[str], None] | None = None,
             protocols: Sequence[str] | None = None, error_estimate: bool = True,
             min_share: float = MIN_SHARE, noise: str = "auto", max_iterations: int = 50,
             model_error: bool = True, scan: ScanOptions | None = None,
             calibration: FitResult | None = None, scheduler: Any = None) -> GapReport:
    """Diagnose the sim-to-real gap of ``model`` (a model file or description) on ``observations``
    (an :class:`Observations`, or a session path: experiment file or CSV record).

    ``effects``: candidate effects (default every installed effect that applies and the model
    lacks); ``holdout``: protocols kept out of the fit and predicted; ``free``: the parameters to
    calibrate (default the model file's free ones); ``max_effects``: rounds of naming;
    ``candidates``: refits per round; ``alpha``: the level of every test; ``workers``: worker
    processes of a finite-element model; ``until`` [s]: only the session's first seconds (e.g. the
    imaged part of a record); ``progress(line)``: what is being done; ``protocols``: read only
    these records of a session path (e.g. leave out records another model describes);
    ``error_estimate``: for a finite-element model, once a candidate's score test is
    significant, solve the calibrated model on a mesh refined 2x and test every candidate again
    with the discretisation error's signature projected out: an effect that explains only what
    a finer mesh would is neither refitted nor named (:mod:`skinkit.inverse.discretisation`);
    ``min_share``: the share of the excess an added effect must remove to be named a cause
    (:mod:`skinkit.gap.verdict`); ``noise``: how a record's noise is modelled (``"auto"``,
    ``"white"``, ``"ar"``: :func:`skinkit.forward.observations.channels_from_record`);
    ``max_iterations``: evaluations each fit may make (the calibration and every refit);
    ``model_error``: a finite-element model's discretisation error is estimated at the
    calibration and carried as noise by every later step (:mod:`skinkit.inverse.approximation`;
    it then replaces ``error_estimate``'s projection); ``scan``: how candidates that declare a
    region are scanned over the tracked points (:mod:`skinkit.gap.scan_step`; None: the defaults);
    ``calibration``: a fit of the same ``free`` parameters on the same observations already made
    (e.g. the session's identification), used as the calibration instead of fitting again (one
    made with the model's error carried, on ``observations`` that carry it, as
    :func:`skinkit.inverse.approximation.refit` returns them, is not estimated again);
    ``scheduler``: a Dask scheduler address (or cluster) to solve every prediction's protocols on
    instead of ``workers``.
    """
    from skinkit.forward import load, model_kind, read_description, region_partitions

    t0 = time.perf_counter()
    say = progress or (lambda _m: None)
    if max_effects < 0 or candidates < 1:
        raise GapError(f"max_effects must be >= 0 and candidates >= 1, got {max_effects}, {candidates}")
    if not 0 < alpha < 1:
        raise GapError(f"alpha must be in (0, 1), got {alpha!r}")
    if not (isinstance(min_share, (int, float)) and 0 < min_share <= 1):
        raise GapError(f"--min-share must be in (0, 1], got {min_share!r}")
    if not (isinstance(max_iterations, int) and max_iterations >= 1):
        raise GapError(f"--max-iterations must be a whole number >= 1, got {max_iterations!r}")
    spec = read_description(model)
    kind = model_kind(spec)

    def loader(s: Mapping[str, Any]) -> Any:
        return load(s, workers=workers, scheduler=scheduler)

    cal = _calibrate(spec, kind, loader, observations, effects=effects, holdout=holdout, free=free,
                     until=until, protocols=protocols, say=say, noise=noise, max_iterations=max_iterations,
                     model_error=model_error, scan=scan, calibration=calibration)
    if cal["model_error"] is not None or cal["failed"] is not None:
        error_estimate = False     # in the noise model already, or its refined solve fails
    state0, r0, theta = cal["state0"], cal["result"], cal["theta"]
    run = _Run(spec=spec, base=cal["base"], observations=cal["observations"], held=cal["held"],
               present=cal["present"], loader=loader, say=say, alpha=alpha, candidates=candidates,
               max_effects=max_effects, error_estimate=error_estimate, state0=state0, current=state0,
               theta_r=list(theta), remaining=list(cal["candidates"]), n_forward=r0.n_forward + 1,
               min_share=float(min_share), max_iterations=int(max_iterations),
               regions=region_partitions(spec), scan=scan)
    if cal["failed"] is not None:
        run.warnings.append(cal["failed"])
    if effects is None:
        _more_of_the_same(run)     # a repeatable effect the model file already has: one more term
    for rnd in range(max(max_effects, 1)):
        if not _round(run, rnd):
            break
    with stage("how far"):
        far = _how_far(run)
    if cal["model_error"] is not None and run.additions:
        from skinkit.gap.final_model import refit_final
        with stage("final model"):
            run.final = refit_final(with_effects(spec, run.tables), run.observations, run.current["result"],
                                    run.theta_r, run.loader, say, run.max_iterations, run.warnings)
    with stage("reporting"):
        return _assemble_report(run, cal, far, t0)


def _calibrate(spec: Mapping[str, Any], kind: str, loader: Callable[..., Any],
               observations: Observations | str | os.PathLike[str], *, effects: Sequence[str] | None,
               holdout: Sequence[str], free: Sequence[str] | None, until: float | None,
               protocols: Sequence[str] | None, say: Callable[[str], None], noise: str = "auto",
               max_iterations: int = 50, model_error: bool = False, scan: ScanOptions | None = None,
               calibration: FitResult | None = None) -> dict[str, Any]:
    """The session read and checked, the candidate effects, and the model calibrated on it:
    ``name``, ``source``, ``observations``, ``held``, ``present`` (the model's effects),
    ``theta`` (free names), ``candidates``, ``result`` (the fit), ``state0`` (:func:`_state`),
    ``base`` (the loaded model, closed)."""
    from skinkit.inverse import fit
    from skinkit.inverse.fit import free_set

    base = loader(spec)
    try:
        name = str(getattr(base, "name", "model"))
        present = [str(t.get("name")) for t in (spec.get("effects") or []) if isinstance(t, Mapping)]
        if not isinstance(observations, Observations):
            from skinkit.forward.session import read_session
            source = str(observations)
            observations = read_session(base, observations, ",".join(holdout) or None,
                                        protocols=",".join(protocols) if protocols else None, noise=noise)
        else:
            source = observations.source
            if holdout:
                observations = observations.with_held_out(list(holdout))
        if until is not None:
            if not until > 0:
                raise GapError(f"until must be > 0 s, got {until!r}")
            observations = observations.until(float(until))
        theta = free_set(base.parameters(), list(free) if free is not None else None).free_names
        if not theta:
            raise GapError(f"model {name!r} has no free parameter: nothing to calibrate before diagnosing "
                           "(mark some free in the model file, or name them with --free)")
        if not len(observations.fitted()):
            raise GapError("session: every protocol is held out; the calibration needs fitted protocols")
        cands = check_effects(kind, present, list(effects) if effects is not None else None)
        check_channels(base, observations)
        check_regions(spec, observations, scan)
        held = observations.held_out()
        say(f"calibrating {name}: {', '.join(theta)} on {len(observations.fitted())} protocol(s)")
        with stage("calibration"):
            given = calibration is not None and sorted(calibration.parameters.free_names) == sorted(theta)
            r0 = calibration if given else fit(base, observations, theta, max_iterations=max_iterations)
        carried, failed = None, None
        if given and observations.model_error is not None and calibration.extra.get("model_error"):
            # a calibration made with the mesh's error carried, on observations that carry it
            carried = calibration.extra["model_error"]
        elif model_error and has_mesh(base):
            from skinkit.inverse.approximation import not_estimated, refit
            try:
                with stage("model error"):
                    r1, carrying = refit(base, observations, r0, theta, fit, progress=say,
                                         max_iterations=max_iterations)
                r0, observations = r1, carrying
                carried, held = r0.extra["model_error"], observations.held_out()
            except SkinkitError as exc:
                # the calibration stands: a model whose refined copy cannot be solved (an
                # instability the finer mesh resolves) is still diagnosed, saying what is missing
                failed = {"kind": "model-error-failed", "where": "model error", "message":
                          f"{not_estimated(exc)}; it is neither carried as noise nor checked, so an "
                          "effect named may be what a finer mesh would explain"}
                say(failed["message"])
        with stage("calibration"):
            state0 = _state(base, r0, observations, held)
    finally:
        base.close()
    return {"name": name, "source": source, "observations": observations, "held": held, "present": present,
            "theta": theta, "candidates": cands, "result": r0, "state0": state0, "base": base,
            "model_error": carried, "failed": failed}


def _round(run: _Run, rnd: int) -> bool:
    """Round ``rnd`` (0-based): locate the residual, score and refit the candidates, name the best
    one that qualifies; True when another round should follow."""
    from skinkit.gap.where import locate

    current = run.current
    run.say(f"round {rnd + 1}: locating the residual (χ²/ν {current['chi2'] / current['dof']:.4g})")
    loc = locate(run.observations, current["prediction"], n_params=current["k"], alpha=run.alpha,
                 regions=run.regions)
    if run.loc0 is None:
        run.loc0 = loc
    values = _values(current["result"])
    spec_r = with_effects(run.spec, run.tables)
    in_model = run.present + [t.get("instance", t["name"]) for t in run.tables]
    entry: dict[str, Any] = {"round": rnd + 1, "model_effects": in_model,
                             "chi2_per_dof": current["chi2"] / current["dof"],
                             "gap_significant": bool(loc.significant), "candidates": [], "named": None}
    if not run.remaining:
        run.rounds.append(entry)
        return False
    rs = scan_round(run, spec_r, values, rnd)
    sens, tests, ok, mesh_only, top = _score(run, spec_r, values, rs)
    values = {**values, **rs.values()}     # region candidates at their best regions: tested, refitted
    gate = _gate(loc, tests, run.alpha)
    if not gate["significant"]:
        top = []             # nothing will be named: no refit
    seps = separability(sens, tests, run.alpha, [t.effect for t in top])
    states = _refit_top(run, top, values, sens, entry, rs)
    records = [candidate_record(t, ok[t.effect], states.get(t.effect), current) for t in tests]
    with stage("separation"):
        _separate(run, seps, records, spec_r, values, sens, tests, rnd)
    if rnd == 0:
        run.first_candidates = records
        run.first_scores = (sens, {t.effect: t for t in tests})
    entry["candidates"] = [c.to_dict() for c in records]
    entry["skipped"] = sens.skipped
    entry["notes"] = sens.notes
    winner, reasons = _choose(run, entry, gate, tests, ok, records, states, rnd)
    for e in mesh_only:
        reasons[e] = ("what it would explain is the mesh's discretisation error (its score test fails "
                      "once that signature is projected out): refine the mesh (skinkit convergence)")
    for e, why in entry.get("screened", {}).items():
        reasons.setdefault(e, why)
    entry["explained_by_discretisation"] = mesh_only
    if run.disc is not None:
        run.disc.setdefault("explains", [])
        run.disc["explains"] += [e for e in mesh_only if e not in run.disc["explains"]]
    entry["not_named"] = reasons
    run.rounds.append(entry)
    if winner is None or len(run.named) >= run.max_effects:
        return False
    return _name(run, winner, states[winner.effect], rnd)


def _score(run: _Run, spec_r: Mapping[str, Any], values: Mapping[str, float], rs: RoundScan
           ) -> tuple[Sensitivities, list[ScoreTest], dict[str, bool], list[str], list[ScoreTest]]:
    """The score tests of the remaining candidates at the current model: ``(sensitivities, tests,
    significant after correction, explained by the mesh alone, the top ones to refit)``; makes
    the discretisation check (once) when a test is significant."""
    from skinkit.gap.score import score_all

    with stage("score sensitivities"):
        sens = collect(spec_r, run.observations, {**values, **rs.values()}, run.theta_r, run.remaining,
                       load=run.loader, progress=run.say)
    run.n_forward += sens.n_forward
    tests = rs.adjust(score_all(sens))
    ok = corrected(tests, run.alpha)
    if run.error_estimate and run.disc is None and any(ok.values()) and has_mesh(run.base):
        with stage("discretisation check"):
            run.disc = discretisation(run.base, run.observations, values, run.state0["prediction"], sens,
                                      run.alpha, run.say)
        run.n_forward += 1
    explained = mesh_only(run.disc, sens, tests, ok, run.alpha, rs.adjust)
    top = [t for t in tests if ok[t.effect] and t.effect not in explained][:run.candidates]
    return sens, tests, ok, explained, top


def _refit_top(run: _Run, top: Sequence[ScoreTest], values: Mapping[str, float], sens: Sensitivities,
               entry: dict[str, Any], rs: RoundScan) -> dict[str, dict[str, Any]]:
    """The refitted states of the ``top`` candidates (none when ``max_effects`` is 0), each in its
    refit form where the round's scans ``rs`` found one, and also from its scan's second place
    where there is one (the better kept, :func:`~skinkit.gap.scan_step.rival_refit`); a refit that
    fails is said and recorded in ``entry["refit_failures"]``."""
    states: dict[str, dict[str, Any]] = {}
    if run.max_effects <= 0:
        return states
    forms = rs.refit_forms()

    def refit(start: Mapping[str, float], form: Any, test: ScoreTest) -> dict[str, Any]:
        return _refit(run.spec, run.tables, run.observations, run.held, {**values, **start}, run.theta_r,
                      test, sens, load=run.loader, say=run.say, max_iterations=run.max_iterations, form=form)
    for t in refit_order(top, run.current["result"]):
        why = screened(t, best_qualifying(states, top, run.current), run.current["result"])
        if why is not None:
            run.say(f"{t.effect} {why}")
            entry.setdefault("screened", {})[t.effect] = why
            continue
        try:
            with stage(f"refit {t.effect}"):
                states[t.effect] = refit({}, forms.get(t.effect), t)
            run.n_forward += states[t.effect]["result"].n_forward + 1
        except SkinkitError as exc:
            run.say(f"refit with {t.effect} failed: {exc}")
            entry.setdefault("refit_failures", {})[t.effect] = str(exc)
            run.warnings.append({"kind": "refit-failed", "where": t.effect, "message":
                                 f"the refit with {t.effect} failed in round {entry['round']}: {exc}"})
        if t.effect in rs.rivals:
            kept = rival_refit(run, t, states.get(t.effect), rs.rivals[t.effect], entry, refit)
            if kept is not None:
                states[t.effect] = kept
    return states


def _separate(run: _Run, seps: Sequence[dict[str, Any]], records: Sequence[EffectScore],
              spec_r: Mapping[str, Any], values: Mapping[str, float], sens: Sensitivities,
              tests: Sequence[ScoreTest], rnd: int) -> None:
    """Mark each non-separable pair on its candidates and rank the protocols that would separate it
    (appended to ``run.separation``)."""
    for sp in seps:
        a, b = sp["effects"]
        if sp["separable"]:
            continue
        for c in records:
            if c.effect == a:
                c.not_separable_from.append(b)
            elif c.effect == b:
                c.not_separable_from.append(a)
        run.say(f"{a} and {b} leave nearly the same signature (|cos| {sp['cosine']:.3f}): ranking protocols")
        best = separating_protocol(spec_r, run.observations, values, run.theta_r, sens, tests, (a, b),
                                   load=run.loader, progress=run.say)
        sp_out = {"effects": [a, b], "cosine": sp["cosine"], "round": rnd + 1}
        if best is not None:
            sp_out.update({"protocol": best["protocol"], "cosine_after": best["cosine"],
                           "ranking": best["ranking"][:5]})
        run.separation.append(sp_out)


def _choose(run: _Run, entry: dict[str, Any], gate: Mapping[str, Any], tests: Sequence[ScoreTest],
            ok: Mapping[str, bool], records: Sequence[EffectScore], states: Mapping[str, dict[str, Any]],
            rnd: int) -> tuple[EffectScore | None, dict[str, str]]:
    """The round's verdict: whether there is a gap (``gate``, :func:`_gate`; recorded in
    ``entry``), the refitted candidate that qualifies with the lowest AIC (or None), and why each
    other refitted one does not."""
    reasons: dict[str, str] = {}
    winner = None
    gap_sig = gate["significant"]
    directed = [t.effect for t in tests if ok[t.effect]] if gap_sig else []
    entry["gap_significant"] = gap_sig
    entry["directed"] = directed
    entry["gate"] = gate
    if rnd == 0:
        run.gap0 = {"significant": gap_sig, "omnibus_significant": gate["omnibus"], "directed": directed,
                    "gate": gate}
    if gap_sig:
        for c in records:
            if c.effect not in states:
                continue
            good, why = qualifies(c, states[c.effect], run.current)
            if not good:
                reasons[c.effect] = why
            elif winner is None or _priority(run, c) < _priority(run, winner):
                winner = c
    return winner, reasons


def _priority(run: _Run, c: EffectScore) -> tuple[bool, float]:
    """Which qualifying candidate a round adds: one whose effect explained at least ``min_share``
    of the first model's excess on its own (a cause, known from the first round's refits; a
    further instance counts as its effect) before one that did not or is not known to, then
    the lowest AIC. Adding a minor contribution first would spend a round that a cause needs."""
    refitted = {x.effect: x for x in run.first_candidates if x.refitted}
    rec = refitted.get(c.effect) or refitted.get(effect_of(c.effect))
    cause = False
    if rec is not None and rec.extra.get("chi2_refit") is not None and run.loc0 is not None:
        e0 = run.state0["chi2"] - noise_factor(run.loc0) * run.state0["dof"]
        cause = e0 > 0 and (run.state0["chi2"] - rec.extra["chi2_refit"]) / e0 >= run.min_share
    return (not cause, float(c.delta_aic))


def _gate(loc: Any, tests: Sequence[ScoreTest], alpha: float) -> dict[str, Any]:
    """Whether there is a gap at family-wise level ``alpha``: in the residual as a whole or one of
    its cells (one Holm family, p-value ``loc.family_p``), or along a candidate's signature (the
    score test is the more powerful test against that alternative; :func:`directed_p`) — two
    families, each at ``alpha``/2 (Bonferroni). When there is none, the located cells lose their
    flags, so that a report never shows a significant cell beside "no significant gap" (a cell
    claims its place only once the gate has opened: gatekeeping keeps the family-wise level).
    A periodic component above the drive's band opens it too (a tone is a gap the noise model
    hid, whatever the χ² says): the line test belongs to the residual's family at
    :data:`skinkit.gap.lines.ALPHA_SHARE` of its level (``loc.family_p``)."""
    half = alpha / 2
    omnibus_p, score_p = float(loc.family_p), directed_p(tests)
    omnibus = bool(omnibus_p <= half)
    significant = omnibus or bool(score_p <= half)
    if not significant:
        loc.significant = False
        for c in loc.cells:
            c.significant = False
    return {"significant": significant, "omnibus": omnibus, "omnibus_p": omnibus_p, "score_p": score_p,
            "level": alpha, "each": half}


def _name(run: _Run, winner: EffectScore, st: dict[str, Any], rnd: int) -> bool:
    """Add ``winner`` to the model at its refitted state; True when another round may follow."""
    run.named.append(winner.effect)
    run.rounds[-1]["named"] = winner.effect
    run.additions.append({"effect": winner.effect, "before": run.current, "after": st, "round": rnd + 1})
    said = {(w["kind"], w["parameter"]) for w in run.warnings if w.get("parameter")}
    for w in st.get("warnings", []):
        if (w["kind"], w.get("parameter")) in said:
            continue          # a parameter refitted again in a later round, said once
        run.warnings.append(w)
        if w["kind"] == "not-converged" or (w["kind"] == "on-bound" and w.get("parameter") in st["added"]):
            run.undermined.setdefault(winner.effect, w["message"])
    run.winners.append(winner)
    run.tables.append(st["table"])
    run.theta_r = run.theta_r + st["added"]
    run.current = st
    run.remaining = [e for e in run.remaining if e != winner.effect]
    _more_of_the_same(run)
    if len(run.named) >= run.max_effects:
        in_model = run.present + [t.get("instance", t["name"]) for t in run.tables]
        run.rounds.append({"round": rnd + 2, "model_effects": in_model,
                           "chi2_per_dof": st["chi2"] / st["dof"], "candidates": [], "named": None,
                           "note": f"--max-effects {run.max_effects} reached"})
        return False
    return True


def _more_of_the_same(run: _Run) -> None:
    """One more instance of each repeatable effect the model now has joins the candidates (a
    further Prony term competes with new effects on equal terms)."""
    from skinkit.gap.score import repeat_candidates

    tables = [t for t in (run.spec.get("effects") or []) if isinstance(t, Mapping)] + list(run.tables)
    for label, _ in repeat_candidates(tables):
        if label not in run.remaining:
            run.remaining.append(label)


def _alone(run: _Run, cal: Mapping[str, Any], label: str) -> float | None:
    """χ² of the first model with ``label`` added and refitted alone (the first round's refit,
    or one made now for an effect first added in a later round); None when it cannot be made."""
    rec = next((c for c in run.first_candidates if c.effect == label and c.refitted), None)
    if rec is not None and rec.extra.get("chi2_refit") is not None:
        return float(rec.extra["chi2_refit"])
    if run.first_scores is None or label not in run.first_scores[1]:
        return None
    sens, tests = run.first_scores
    try:
        start = {**_values(cal["result"]), **run.held_regions}
        st = _refit(run.spec, [], run.observations, run.held, start, cal["theta"], tests[label], sens,
                    load=run.loader, say=run.say, max_iterations=run.max_iterations,
                    form=run.held_forms.get(label))
    except SkinkitError as exc:
        run.say(f"refit of the first model with {label} alone failed: {exc}")
        return None
    run.n_forward += st["result"].n_forward + 1
    return float(st["chi2"])


def _how_far(run: _Run) -> dict[str, Any]:
    """How far the named effects close the gap: shrinkage overall, held out and per cell of the
    first round's location, and the final model's located residual (None when nothing is named)."""
    from skinkit.gap.where import cell_chi2, locate

    final, state0, loc0, named = run.current, run.state0, run.loc0, run.named
    cells_before = [(c.axis, c.label) for c in loc0.cells]
    after = (cell_chi2(run.observations, final["prediction"], cells_before, n_params=final["k"],
                       regions=run.regions) if named else {})
    shrink_cells = []
    for c in loc0.cells:
        a2, d2 = after.get((c.axis, c.label), (c.chi2, c.dof))
        row = {"axis": c.axis, "label": c.label, "before": c.chi2_per_dof,
               "after": a2 / d2 if d2 > 0 else None,
               "shrinkage": fraction(c.chi2 - c.dof, a2 - d2) if named else 0.0}
        shrink_cells.append(row)
    overall = fraction(state0["chi2"] - state0["dof"], final["chi2"] - final["dof"]) if named else 0.0
    held_out = None
    if state0["held_n"]:
        held_out = fraction(state0["held_chi2"] - state0["held_n"], final["held_chi2"] - final["held_n"]) \
            if named else 0.0
    loc_after = (locate(run.observations, final["prediction"], n_params=final["k"], alpha=run.alpha,
                        regions=run.regions) if named else None)
    return {"overall": overall, "held_out": held_out, "cells": shrink_cells, "loc_after": loc_after}


def _final_parameters(c: EffectScore, final: Mapping[str, Any]) -> None:
    """Replace an added candidate's parameter values and errors by the final model's."""
    r: FitResult = final["result"]
    for n, p in (c.parameters or {}).items():
        if n in r.parameters.names:
            se = num(r.se.get(n))
            v = float(r.parameters[n])
            p.update(value=v, se=se, interval=None if se is None else [v - 1.96 * se, v + 1.96 * se])


def _verdict(run: _Run, cal: Mapping[str, Any], loc_final: Any) -> dict[str, Any]:
    """Roles and shares on the candidates, ``remaining``, ``warnings``, ``noise`` and the causes."""
    from skinkit import registry

    final = dict(run.current, result=run.final_fit)
    # an added effect is reported by the record of the round that added it
    won = {w.effect: w for w in run.winners}
    first = {c.effect for c in run.first_candidates}
    cands = [won.get(c.effect, c) for c in run.first_candidates]
    cands += [w for w in run.winners if w.effect not in first]
    added = [a["effect"] for a in run.additions]
    for c in cands:
        if c.effect in added:
            _final_parameters(c, final)
    dicts = [c.to_dict() for c in cands]
    kappa = noise_factor(run.loc0)
    known = registry.names("skinkit.effects")
    firsts = {}
    for lab in added:
        firsts.setdefault(effect_of(lab), lab)
    alone = {lab: _alone(run, cal, lab) for lab in firsts.values()}
    causes, minor = assign_roles(dicts, run.additions, known, run.min_share, run.undermined, kappa,
                                 alone=alone, chi2_first=run.state0["chi2"], dof_first=run.state0["dof"])
    for c, d in zip(cands, dicts, strict=True):
        c.extra.update({k: d[k] for k in ("role", "share", "role_reason") if k in d})
    rem = remaining(loc_final, final, run.state0, kappa)
    warns = fit_warnings(cal["result"], "the calibration", cal["theta"]) + list(run.warnings)
    warns += record_warnings(run.observations, final["prediction"], bool(rem["significant"]))
    if rem["significant"] and rem["unexplained_share"] >= SMALL_REMAINDER and run.max_effects \
            and len(added) >= run.max_effects:
        warns.append({"kind": "max-effects-reached", "where": "diagnosis", "message":
                      f"the diagnosis stopped at --max-effects {run.max_effects} while the remainder is "
                      "still significant: more rounds may find more"})
    return {"candidates": cands, "causes": causes, "minor": minor, "added": added, "remaining": rem,
            "warnings": warns, "noise": noise_summary(run.observations)}


def _assemble_report(run: _Run, cal: Mapping[str, Any], far: Mapping[str, Any], t0: float) -> GapReport:
    """The :class:`GapReport` of a finished diagnosis (``cal``: :func:`_calibrate`'s, ``far``:
    :func:`_how_far`'s; ``t0``: its start, ``time.perf_counter``)."""
    r0, theta, state0, final, loc0 = cal["result"], cal["theta"], run.state0, run.current, run.loc0
    observations, loc_after, fr = run.observations, far["loc_after"], run.final_fit
    v = _verdict(run, cal, loc_after if loc_after is not None else loc0)
    fit_d = {"parameters": {n: float(r0.parameters[n]) for n in theta}, "chi2_per_dof": r0.chi2_per_dof,
             "n_forward": r0.n_forward, "se": {n: num(r0.se.get(n)) for n in theta}, "aic": r0.aic,
             "held_out": r0.held_out, "converged": r0.converged, "free": list(theta)}
    extra = {"points": _points(observations),
             "point_map_after": {} if loc_after is None else
             {k: [num(x) for x in v] for k, v in loc_after.point_map.items()},
             "separation": run.separation, "rounds": run.rounds, "messages": [],
             "discretisation": None if run.disc is None else {k: v for k, v in run.disc.items() if k != "e"},
             "model_error": cal["model_error"],
             "effects_tested": list(cal["candidates"]), "alpha": run.alpha, "min_share": run.min_share,
             "chi2": {"before": state0["chi2"], "after": final["chi2"], "dof_before": state0["dof"],
                      "dof_after": final["dof"], "held_out_before": state0["held_chi2"],
                      "held_out_after": final["held_chi2"], "held_out_samples": state0["held_n"]},
             "final_parameters": {n: float(fr.parameters[n]) for n in run.theta_r},
             "final_se": {n: num(fr.se.get(n)) for n in run.theta_r},
             "final_model_error": None if run.final is None else run.final.extra.get("model_error"),
             "effects_model": [dict(t) for t in run.tables], "minor": v["minor"],
             "noise": v["noise"], "remaining": v["remaining"], "warnings": v["warnings"],
             "n_forward": run.n_forward, "wall_s": time.perf_counter() - t0, "region_scan": run.scans,
             "series": diagnosis_series(observations, state0, final, run.additions)}
    gap_d = _gap_dict(loc0)
    gap_d.update(run.gap0 or {"significant": bool(loc0.significant),
                              "omnibus_significant": bool(loc0.significant), "directed": []})
    report = GapReport(cal["name"], cal["source"], fit=fit_d, gap=gap_d, candidates=v["candidates"],
                       named=v["causes"], shrinkage={"overall": far["overall"], "held_out": far["held_out"],
                                                     "cells": far["cells"]}, extra=extra)
    first = run.rounds[0] if run.rounds else {}
    sig_tests = [c["effect"] for c in first.get("candidates", []) if c.get("significant")]
    refit_any = any(c.get("refitted") for r in run.rounds for c in r.get("candidates", []))
    cpd = state0["chi2"] / state0["dof"]
    report.extra["messages"] = messages(report.to_dict(), loc0, run.gap0 or {}, cpd, v["added"],
                                        run.min_share, sig_tests, refit_any)
    return report


__all__ = ["AIC_MARGIN", "GapError", "check_effects", "diagnose", "write_report"]
