"""``skinkit fit``: identify a model's free parameters from a session."""

from __future__ import annotations

import json
import os
from pathlib import Path

import click

from skinkit.errors import SkinkitError


def _names(text: str | None) -> list[str] | None:
    return [s.strip() for s in text.split(",") if s.strip()] if text else None


def _checkpoint(path: Path, payload: dict) -> None:
    """Write ``payload`` as JSON atomically (a kill leaves the previous checkpoint whole)."""
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(json.dumps(payload))
    os.replace(tmp, path)


@click.command("fit")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.argument("session", type=click.Path(dir_okay=False))
@click.option("--free", default=None, help="free parameters (comma-separated; default: the model's)")
@click.option("--objective", "weighting", default="noise", show_default=True,
              help="weighting: noise, unweighted, displacement, threshold, robot-only, strain")
@click.option("--optimiser", default="scipy-lsq", show_default=True, help="a skinkit.optimisers plugin")
@click.option("--starts", type=click.IntRange(min=1), default=1, show_default=True,
              help="multi-start: this many starts from a space-filling design; every start is kept")
@click.option("--holdout", default=None, help="protocols kept out of the fit and predicted (comma-separated)")
@click.option("--segments", type=click.Choice(["cycles"]), default=None,
              help="split every record into protocols first (cycles: one per loading cycle, "
                   "named <protocol>-cycle-<k>), so --holdout can name a cycle")
@click.option("--resume", is_flag=True,
              help="continue a killed fit from its last completed iteration (same --out)")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="directory for fit.json and the checkpoint (default: fit-<model name>)")
@click.option("--workers", type=click.IntRange(min=1), default=None, help="worker processes")
@click.option("--json", "as_json", is_flag=True, help="print the result as JSON")
def fit(model_file: str, session: str, free: str | None, weighting: str, optimiser: str, starts: int,
        holdout: str | None, segments: str | None, resume: bool, out_dir: str | None, workers: int | None,
        as_json: bool) -> None:
    """Fit MODEL_FILE's free parameters to SESSION (experiment file or CSV record)."""
    import numpy as np

    from skinkit.forward import load, read_observations
    from skinkit.inverse import WEIGHTINGS, fit_json
    from skinkit.inverse import fit as run_fit
    from skinkit.inverse.fit import free_set
    from skinkit.inverse.scaling import Scaling

    if weighting not in WEIGHTINGS:
        raise SkinkitError(f"--objective {weighting!r}: must be one of {', '.join(WEIGHTINGS)}")
    model = load(model_file, workers=workers)
    axis = str(getattr(model, "axis", "z"))
    obs = read_observations(session, held_out=_names(holdout) or [], axis=axis if axis in "xyz" else "z",
                            segments=segments)
    out = Path(out_dir) if out_dir else Path.cwd() / f"fit-{model.name}"
    ckpt = out / "checkpoint.json"
    if resume and not ckpt.is_file():
        raise SkinkitError(f"--resume: no checkpoint in {out} "
                           "(run without --resume first, with the same --out)")
    out.mkdir(parents=True, exist_ok=True)
    params = free_set(model.parameters(), _names(free))
    names = params.free_names
    sc = Scaling.for_parameters(params, names)
    lo, hi = sc.bounds()
    # the starts: the model's values, then a scrambled Sobol design in the scaled box
    x_starts = [sc.to_scaled(params.free_vector())]
    if starts > 1:
        from scipy.stats import qmc
        box_lo = np.where(np.isfinite(lo), lo, x_starts[0] - 1)
        box_hi = np.where(np.isfinite(hi), hi, x_starts[0] + 1)
        u = qmc.Sobol(len(names), scramble=True, seed=0).random(starts - 1)
        x_starts += list(qmc.scale(u, box_lo, box_hi))
    done: list[dict] = []
    state = {"best_x": None, "start": 0}
    if resume:
        saved = json.loads(ckpt.read_text())
        if saved.get("free") != names or saved.get("session") != str(session):
            raise SkinkitError(f"--resume: the checkpoint in {out} is of another fit "
                               f"(free {saved.get('free')}, session {saved.get('session')})")
        done = saved["starts_done"]
        state = {"best_x": saved.get("best_x"), "start": saved.get("start", len(done))}

    def progress(i: int, phi: float, x: dict) -> None:
        best = state.get("best_phi")
        if best is None or phi < best:
            state["best_phi"] = phi
            state["best_x"] = [x[n] for n in names]
        _checkpoint(ckpt, {"free": names, "session": str(session), "starts_done": done,
                           "start": state["start"], "best_x": state["best_x"], "evaluations": i})
        if not as_json:
            vals = ", ".join(f"{n} = {v:.4g}" for n, v in x.items())
            click.echo(f"  start {state['start'] + 1}/{starts} evaluation {i}: objective {phi:.6g}  [{vals}]",
                       err=True)

    results = []
    for k in range(state["start"], starts):
        state["start"] = k
        if resume and state.get("best_x") is not None and k == saved.get("start"):
            start_vals = dict(zip(names, state["best_x"], strict=True))
        else:
            start_vals = dict(zip(names, sc.to_values(x_starts[k]).tolist(), strict=True))
            state["best_phi"], state["best_x"] = None, None
        r = run_fit(model, obs, names, weighting=weighting, optimiser=optimiser, start=start_vals,
                    progress=progress)
        j = fit_json(r)
        done.append({"start": start_vals, "objective": j["objective"],
                     "parameters": {n: j["parameters"][n]["value"] for n in names},
                     "converged": j["converged"]})
        results.append((j, r))
    if not results:
        raise SkinkitError(f"--resume: every start of the fit in {out} was already done")
    best, best_result = min(results, key=lambda jr: jr[0]["objective"])
    if str(session).lower().endswith((".h5", ".hdf5")):
        from skinkit.store import open_experiment
        best_result.extra["starts"] = done
        with open_experiment(session, "a") as exp:
            exp.write_fit(f"fit-{model.name}", best_result)
    best["starts"] = done
    best["model"] = model.name
    best["session"] = str(session)
    _checkpoint(out / "fit.json", best)
    ckpt.unlink(missing_ok=True)
    if hasattr(model, "close"):
        model.close()
    if as_json:
        click.echo(json.dumps(best, indent=2, default=float))
        return
    status = "converged" if best["converged"] else "NOT converged"
    click.echo(f"{model.name} on {session}: chi2/dof {best['chi2_per_dof']:.4g}, {best['n_forward']} forward "
               f"solves with sensitivities, {best['wall_s']:.1f} s, {status}")
    for n in names:
        p = best["parameters"][n]
        if p.get("identifiable") is False:
            click.echo(f"  {n:28s} not identifiable from these protocols (see below)")
        else:
            click.echo(f"  {n:28s} {p['value']:.6g} ± {p['se']:.2g} {p['unit']}")
    for pr in best["identifiability"]["problems"]:
        click.echo(f"  ! {pr['message']}")
    for p, v in best["held_out"].items():
        click.echo(f"  held out {p}: rms {v:.3g} noise levels")
    click.echo(f"wrote {out / 'fit.json'}")
