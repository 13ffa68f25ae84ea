"""``skinkit fit``: identify a model's free parameters from a session."""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable
from pathlib import Path

import click

from skinkit import jsonio
from skinkit.cli._paths import check_name, check_result_files, name_callback
from skinkit.cli._scheduler import scheduler_callback
from skinkit.cli._types import FiniteFloat
from skinkit.errors import SkinkitError
from skinkit.forward.session import read_session, split_names
from skinkit.units import unit_suffix


def _checkpoint(path: Path, payload: dict) -> None:
    """Write ``payload`` as JSON atomically (a kill leaves the previous checkpoint whole)."""
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(jsonio.dumps(payload))
    os.replace(tmp, path)


def _value(text: str, unit: str, where: str) -> float:
    from skinkit.fem.model import quantity
    text = text.strip()
    try:
        return float(text)
    except ValueError:
        return float(quantity(text, unit, where))


def _bound(item: str, params) -> tuple[str, float, float]:
    name, eq, rng = item.partition("=")
    name = name.strip()
    lo, colon, hi = rng.partition(":")
    if not eq or not colon:
        raise SkinkitError(f"--bounds {item!r}: expected NAME=LOWER:UPPER")
    if name not in params:
        raise SkinkitError(f"--bounds {name!r}: no such parameter; the model has {params.names}")
    unit = params.param(name).unit
    return name, _value(lo, unit, f"--bounds {name}"), _value(hi, unit, f"--bounds {name}")


@click.command("fit")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.argument("session", type=click.Path(dir_okay=False))
@click.option("--free", default=None, help="free parameters (comma-separated; default: the model's)")
@click.option("--objective", "weighting", default="noise", show_default=True,
              help="weighting: noise, unweighted, displacement, threshold, robot-only, strain")
@click.option("--optimiser", default="scipy-lsq", show_default=True,
              help="a skinkit.optimisers plugin (skinkit plugins lists them)")
@click.option("--start", "start_items", multiple=True, metavar="NAME=VALUE",
              help="start a free parameter here (SI value or '<number> <unit>'), repeatable")
@click.option("--bounds", "bound_items", multiple=True, metavar="NAME=LOWER:UPPER",
              help="narrow a parameter's bounds for the fit (SI or with units), repeatable")
@click.option("--starts", type=click.IntRange(min=1), default=1, show_default=True,
              help="multi-start: this many starts from a space-filling design; every start is kept")
@click.option("--protocols", default=None,
              help="read only these records of SESSION (comma-separated; default all)")
@click.option("--holdout", default=None, help="protocols kept out of the fit and predicted (comma-separated)")
@click.option("--segments", type=click.Choice(["cycles"]), default=None,
              help="split every record into protocols first (cycles: one per loading cycle, "
                   "named <protocol>-cycle-<k>), so --holdout can name a cycle")
@click.option("--until", "until_s", type=FiniteFloat(min=0, min_open=True), default=None,
              help="fit only the first part of every record, up to this time [s]")
@click.option("--ftol", type=FiniteFloat(min=0, min_open=True), default=1e-6, show_default=True,
              help="stop when the objective changes by less than this, relatively")
@click.option("--xtol", type=FiniteFloat(min=0, min_open=True), default=1e-3, show_default=True,
              help="stop when the step in scaled parameters is below this")
@click.option("--max-iterations", type=click.IntRange(min=1), default=50, show_default=True,
              help="at most this many forward evaluations per start")
@click.option("--resume", is_flag=True,
              help="continue a killed fit from its last completed evaluation (same --out)")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="directory for fit.json, model.toml (the calibrated model), plots and the checkpoint "
                   "(default: the fit's --name, in the current directory)")
@click.option("--plots", is_flag=True, help="write plots of the fit to --out")
@click.option("--name", "fit_name", default=None, callback=name_callback("fit name"),
              help="name of the fit stored in an experiment-file SESSION (default: fit-<model name>)")
@click.option("--overwrite", is_flag=True,
              help="replace a fit of that name already stored in SESSION, and fit.json and model.toml "
                   "in --out")
@click.option("--error-estimate", is_flag=True,
              help="after the fit, solve once on a mesh refined 2x and report the discretisation error "
                   "beside the residual and each parameter's bias from it (finite-element models)")
@click.option("--model-error/--no-model-error", default=True, show_default=True,
              help="a finite-element model: estimate its mesh's discretisation error at the fit (a "
                   "mesh refined 2x), carry it as noise and fit again (the approximation-error "
                   "approach); the result states it per channel against the noise")
@click.option("--workers", type=click.IntRange(min=1), default=None, help="worker processes")
@click.option("--scheduler", default=None, metavar="ADDRESS", callback=scheduler_callback,
              help="a Dask scheduler address to solve the protocols on instead of --workers (reached "
                   "before any work starts)")
@click.option("--json", "as_json", is_flag=True, help="print the result as JSON")
def fit(model_file: str, session: str, free: str | None, weighting: str, optimiser: str,
        start_items: tuple[str, ...], bound_items: tuple[str, ...], starts: int,
        holdout: str | None, segments: str | None, until_s: float | None, ftol: float, xtol: float,
        max_iterations: int, protocols: str | None, resume: bool, out_dir: str | None, plots: bool,
        fit_name: str | None, overwrite: bool, error_estimate: bool, model_error: bool,
        workers: int | None, scheduler: str | None, as_json: bool) -> None:
    """Fit MODEL_FILE's free parameters to SESSION (experiment file or CSV record).

    --out receives fit.json and model.toml: the calibrated model, MODEL_FILE with the fitted values
    written in and a [calibration] table (the session, date, version, objective and each fitted
    parameter's value and 95 % interval); predict with it like any model file.

    Every evaluation is kept under --out until the fit ends, so a killed fit run again with
    --resume replays what was done (no forward solve repeated) and goes on to the same optimum.
    """
    import shutil

    from skinkit.cli._progress import progress
    from skinkit.forward import load

    _check_choices(weighting, optimiser)
    model = load(model_file, workers=workers, scheduler=scheduler)
    bar = progress(stage="fit").start()   # on stderr, also with --json
    try:
        if error_estimate:
            from skinkit.inverse.discretisation import has_mesh
            if not has_mesh(model):
                raise SkinkitError(f"--error-estimate: model {model.name!r} is lumped; it has no mesh whose "
                                   "discretisation error could be estimated")
        obs = read_session(model, session, holdout, segments, protocols=protocols)
        if until_s is not None:
            obs = obs.until(until_s)
        fit_name = fit_name if fit_name is not None else f"fit-{model.name}"
        stores = str(session).lower().endswith((".h5", ".hdf5"))
        # default: named after the fit (fit-<model name> unless --name), in the current directory
        out = Path(out_dir) if out_dir else Path.cwd() / check_name(fit_name, "--name")
        evals_dir = out / "evaluations"
        state_file = out / "checkpoint.json"
        params, bounds, given = _fit_parameters(model, free, bound_items, start_items)
        names = params.free_names
        _check_centres(model, params, obs, given)
        # what makes two runs the same fit: a resumed run must match it exactly
        identity = {"model": str(Path(model_file).resolve()), "session": str(Path(session).resolve()),
                    "free": names, "objective": weighting, "optimiser": optimiser, "starts": starts,
                    "holdout": split_names(holdout), "start": given,
                    "bounds": {k: list(v) for k, v in bounds.items()}, "segments": segments, "until": until_s,
                    "protocols": split_names(protocols),
                    "ftol": ftol, "xtol": xtol, "max_iterations": max_iterations}
        _check_out(out, state_file, identity, resume=resume, session=session, stores=stores,
                   fit_name=fit_name,
                   overwrite=overwrite)
        if not resume:   # a fresh fit: evaluations of an earlier one in this --out are not its own
            shutil.rmtree(evals_dir, ignore_errors=True)
        out.mkdir(parents=True, exist_ok=True)
        _checkpoint(state_file, identity)
        sc, x_starts = _start_points(params, names, starts)

        def run_start(k: int, start_vals: dict[str, float], progress) -> object:
            from skinkit.inverse import fit as run_fit
            return run_fit(model, obs, names, weighting=weighting, optimiser=optimiser, start=start_vals,
                           ftol=ftol, xtol=xtol, max_iterations=max_iterations, bounds=bounds or None,
                           checkpoint=evals_dir / f"start-{k:03d}", progress=progress)

        results, done = _run_starts(run_start, sc, x_starts, names, bar.say)
        best_result = min(results, key=lambda r: r.objective)
        best_result.starts = done
        from skinkit.inverse.discretisation import has_mesh
        if model_error and has_mesh(model):
            best_result, obs = _carry_model_error(model, obs, best_result, names, bar.say,
                                                  weighting=weighting, optimiser=optimiser, ftol=ftol,
                                                  xtol=xtol, max_iterations=max_iterations,
                                                  bounds=bounds or None)
        if error_estimate:
            from skinkit.inverse.discretisation import attach, estimate
            attach(best_result, estimate(model, obs, best_result.parameters, names, weighting=weighting,
                                         progress=lambda m: bar.say(f"  {m}")))
        if stores:
            from skinkit.store import open_experiment
            with open_experiment(session, "a") as exp:
                exp.write_fit(fit_name, best_result)
        best = _result_json(best_result, results, model.name, session, fit_name if stores else None)
        if plots:
            from skinkit.inverse.plots import fit_plots
            best["plots"] = [str(p) for p in fit_plots(model, obs, best_result, out)]
        _checkpoint(out / "fit.json", best)
        best["calibrated_model"] = str(_write_model(model_file, session, best_result, names, weighting, out))
        # the fit is whole: its evaluations are no longer needed to resume it
        shutil.rmtree(evals_dir, ignore_errors=True)
        state_file.unlink(missing_ok=True)
    finally:
        bar.stop(ok=sys.exc_info()[0] is None)
        model.close()
    if as_json:
        click.echo(jsonio.dumps(best, indent=2, default=float))
        return
    _echo_summary(best, model.name, session, best_result.wall_s, names, out)


def _check_centres(model, params, obs, given: dict[str, float]) -> None:
    """A region effect's (a scar's) centre, from the model file or --start, lies where the session's
    points are tracked (:func:`skinkit.gap.scan_step.check_centres`)."""
    from skinkit.gap.scan_step import check_centres

    check_centres(getattr(model, "effects", []), params.values(), obs, list(given))


def _carry_model_error(model, obs, result, names: list[str], say, **options):
    """``(result, observations)`` refitted with the model's discretisation error carried
    (:func:`skinkit.inverse.approximation.refit`); when the estimate fails, the plain fit and
    observations, with ``extra["model_error_failed"]`` saying why."""
    from skinkit.inverse import fit as run_fit
    from skinkit.inverse.approximation import not_estimated, refit

    starts_kept = result.starts
    try:
        result, obs = refit(model, obs, result, names, run_fit, progress=lambda m: say(f"  {m}"), **options)
    except SkinkitError as exc:   # the plain fit stands, and says what it lacks
        result.extra["model_error_failed"] = (
            f"{not_estimated(exc)}; the fit does not carry it, so its intervals are the noise's alone")
        say(f"warning: {result.extra['model_error_failed']}")
    result.starts = starts_kept
    return result, obs


def _result_json(best_result, results: list, model_name: str, session: str, stored_as: str | None) -> dict:
    """fit.json: the best start's result with the counts summed over every start."""
    from skinkit.inverse import fit_json

    best = fit_json(best_result)
    best["n_forward"] = sum(r.n_forward for r in results)
    best["n_sensitivity"] = sum(r.n_sensitivity for r in results)
    best["n_replayed"] = sum(r.extra.get("n_replayed", 0) for r in results)
    best["model"] = model_name
    best["session"] = str(session)
    if stored_as is not None:
        best["stored_as"] = stored_as
    return best


def _check_choices(weighting: str, optimiser: str) -> None:
    """--objective is a known weighting and --optimiser an installed plugin."""
    from skinkit import registry
    from skinkit.inverse import WEIGHTINGS

    if weighting not in WEIGHTINGS:
        raise SkinkitError(f"--objective {weighting!r}: must be one of {', '.join(WEIGHTINGS)}")
    if optimiser not in registry.names("skinkit.optimisers"):
        raise SkinkitError(f"--optimiser {optimiser!r} is not installed; installed: "
                           f"{', '.join(registry.names('skinkit.optimisers'))}")


def _fit_parameters(model, free: str | None, bound_items: tuple[str, ...], start_items: tuple[str, ...]
                    ) -> tuple[object, dict[str, tuple[float, float]], dict[str, float]]:
    """The model's parameters with --free, --bounds and --start applied: ``(parameters, bounds
    (name -> (lower, upper) [SI]), the given starts (name -> SI))``, each option checked."""
    from skinkit.inverse.fit import free_set, with_bounds

    # an empty --free is refused (by free_set), not read as "the model's own free parameters"
    params = free_set(model.parameters(), None if free is None else split_names(free))
    bounds = {}
    for item in bound_items:
        name, lo, hi = _bound(item, params)
        bounds[name] = (lo, hi)
    if bounds:
        params = with_bounds(params, bounds)
    names = params.free_names
    given = {}
    for item in start_items:
        name, eq, val = item.partition("=")
        name = name.strip()
        if not eq or name not in params:
            raise SkinkitError(f"--start {item!r}: expected NAME=VALUE with NAME one of {params.names}")
        if name not in names:
            raise SkinkitError(f"--start {name}: not a free parameter (free: {', '.join(names)})")
        v = _value(val, params.param(name).unit, f"--start {name}")
        p = params.param(name)
        if not p.lower <= v <= p.upper:
            raise SkinkitError(f"--start {name} = {v:g} {p.unit} is outside its bounds "
                               f"[{p.lower:g}, {p.upper:g}]")
        given[name] = v
    params = params.with_values(given) if given else params
    return params, bounds, given


def _check_out(out: Path, state_file: Path, identity: dict, *, resume: bool, session: str, stores: bool,
               fit_name: str, overwrite: bool) -> None:
    """Before the fit runs: --resume has this fit's checkpoint, the session does not already
    hold a fit of that name, --out holds no fit.json (unless --overwrite)."""
    if resume:
        if not state_file.is_file():
            raise SkinkitError(f"--resume: no checkpoint in {out} "
                               "(run without --resume first, with the same --out)")
        saved = json.loads(state_file.read_text())
        diff = sorted(k for k in identity if saved.get(k) != identity[k])
        if diff:
            raise SkinkitError(f"--resume: the checkpoint in {out} is of another fit (it differs in "
                               f"{', '.join(diff)})")
    if stores and not overwrite:   # checked before the fit runs, not after it
        from skinkit.store import open_experiment
        with open_experiment(session) as exp:
            if fit_name in exp.fit_names():
                raise SkinkitError(f"{session} already holds a fit named {fit_name!r}: give another --name, "
                                   "or --overwrite to replace it")
    if not resume:   # a finished fit's fit.json is a result too: not replaced silently by a new fit
        check_result_files(out, ("fit.json", "model.toml"), "--out", overwrite=overwrite)


def _write_model(model_file: str, session: str, result, names: list[str], weighting: str, out: Path) -> Path:
    """``out/model.toml``: the model file with the fitted values and their 95 % intervals
    (:mod:`skinkit.inverse.calibrated`)."""
    from skinkit.forward import read_description
    from skinkit.inverse.calibrated import write_calibrated

    values = {n: float(result.parameters[n]) for n in names}
    se = {n: result.se.get(n) for n in names}
    return write_calibrated(out, read_description(model_file), values, se, session=session,
                            objective=weighting, command="skinkit fit", model_file=model_file,
                            notes={"chi2_per_dof": result.chi2_per_dof, "converged": result.converged})


def _start_points(params, names: list[str], starts: int) -> tuple[object, list]:
    """The fit's scaling and its ``starts`` scaled start points (each (len(names),)): the model's
    values, then a scrambled Sobol design in the scaled box."""
    import warnings

    import numpy as np

    from skinkit.inverse.scaling import Scaling

    sc = Scaling.for_parameters(params, names)
    lo, hi = sc.bounds()
    x_starts = [sc.to_scaled(params.free_vector())]
    if starts > 1:
        from scipy.stats import qmc
        box_lo = np.where(np.isfinite(lo), lo, x_starts[0] - 1)
        box_hi = np.where(np.isfinite(hi), hi, x_starts[0] + 1)
        with warnings.catch_warnings():   # any count is fine here, not only powers of two
            warnings.simplefilter("ignore")
            u = qmc.Sobol(len(names), scramble=True, seed=0).random(starts - 1)
        x_starts += list(qmc.scale(u, box_lo, box_hi))
    return sc, x_starts


def _run_starts(run_start, sc, x_starts: list, names: list[str], say: Callable[[str], None]
                ) -> tuple[list, list[dict]]:
    """Fit from every start (``run_start(k, start values, progress)``): the results and one record
    per start (a failed one kept with its reason, unless it is the only start); each evaluation
    and failure said by ``say(line)`` (stderr)."""
    from skinkit.inverse.fit import FitError

    starts = len(x_starts)
    results, done, failures = [], [], []
    for k in range(starts):
        start_vals = dict(zip(names, sc.to_values(x_starts[k]).tolist(), strict=True))

        def progress(i: int, phi: float, x: dict, k: int = k) -> None:
            vals = ", ".join(f"{n} = {v:.4g}" for n, v in x.items())
            say(f"  start {k + 1}/{starts} evaluation {i}: objective {phi:.6g}  [{vals}]")

        try:
            r = run_start(k, start_vals, progress)
        except FitError as exc:
            if starts == 1:
                raise
            # a start the model cannot solve (a design point breaking a constraint of the
            # model): kept as a failed start, the others go on
            failures.append(str(exc))
            done.append({"start": start_vals, "failed": str(exc)})
            say(f"  start {k + 1}/{starts} failed: {exc}")
            continue
        done.append({"start": start_vals, "objective": r.objective, "converged": r.converged,
                     "parameters": {n: r.parameters[n] for n in names}, "n_forward": r.n_forward,
                     "n_replayed": r.extra.get("n_replayed", 0)})
        results.append(r)
    if not results:
        raise SkinkitError(f"every start of the fit failed; the first: {failures[0]}")
    return results, done


def _echo_summary(best: dict, model_name: str, session: str, wall_s: float, names: list[str],
                  out: Path) -> None:
    """The fit in lines: χ²/ν and cost, each free parameter with its 95 % interval, problems,
    held-out errors, the discretisation check, plots."""
    status = "converged" if best["converged"] else "NOT converged"
    click.echo(f"{model_name} on {session}: chi2/dof {best['chi2_per_dof']:.4g}, {best['n_forward']} forward "
               f"solves ({best['n_sensitivity']} with sensitivities), {wall_s:.1f} s, {status}")
    for n in names:
        p = best["parameters"][n]
        u = unit_suffix(p["unit"])
        if p.get("identifiable") is False:
            click.echo(f"  {n:28s} {p['value']:.6g}{u}: NOT identifiable from these protocols (see below)")
        else:
            click.echo(f"  {n:28s} {p['value']:.6g} ± {1.96 * p['se']:.2g}{u} (95 %)"
                       if p["se"] is not None else f"  {n:28s} {p['value']:.6g}{u}: undetermined")
    for n in names:
        side = best["parameters"][n].get("on_bound")
        if side:
            click.echo(f"  ! {n} sits on its {side} bound: the fit was stopped by the bound, not by the data "
                       "(its interval means little)")
    for pr in best["identifiability"]["problems"]:
        click.echo(f"  ! {pr['message']}")
    for p, v in best["held_out"].items():
        click.echo(f"  held out {p}: rms {v:.3g} noise levels")
    if best.get("model_error_failed"):
        click.echo(f"  ! {best['model_error_failed']}")
    if best.get("model_error"):
        from skinkit.inverse.approximation import describe as describe_error
        for line in describe_error(best["model_error"]):
            click.echo(line)
    if "discretisation" in best:
        from skinkit.inverse.discretisation import describe
        for line in describe(best["discretisation"]):
            click.echo(f"  {line}")
    for p in best.get("plots", []):
        click.echo(f"  plot {p}")
    click.echo(f"wrote {out / 'fit.json'}")
    click.echo(f"wrote {best['calibrated_model']} (the calibrated model)")
