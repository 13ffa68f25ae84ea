"""``skinkit grid`` and ``skinkit profile-likelihood``: the objective over two parameters (thesis Fig 7-10),
and the profile likelihood of one."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import click

from skinkit import jsonio
from skinkit.cli._paths import check_result_files
from skinkit.cli._progress import progress
from skinkit.errors import SkinkitError
from skinkit.forward.session import read_session, split_names
from skinkit.units import unit_suffix


def _session(model_file: str, session: str, holdout: str | None, workers: int | None) -> tuple[Any, Any]:
    from skinkit.forward import load

    model = load(model_file, workers=workers)
    obs = read_session(model, session, holdout)
    return model, obs


def _read_fit(path: str) -> dict[str, Any]:
    """A ``skinkit fit`` result (``fit.json``): its parameters, free names, covariance and inflation."""
    try:
        d = json.loads(Path(path).read_text())
        pars = d["parameters"]
        names = [n for n, p in pars.items() if p.get("free")]
        values = {n: float(p["value"]) for n, p in pars.items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise SkinkitError(f"--at {path}: not a skinkit fit result (fit.json): "
                           f"{type(exc).__name__}: {exc}") from None
    cov = None
    se = [pars[n].get("se") for n in names]
    if d.get("correlation") is not None and all(s is not None and math.isfinite(s) for s in se):
        import numpy as np

        cov = np.asarray(d["correlation"], float) * np.outer(se, se)
    inflation = float((d.get("identifiability") or {}).get("inflation", 1.0))
    return {"names": names, "values": values, "covariance": cov, "inflation": inflation,
            "se": dict(zip(names, se, strict=True))}


def _say(bar: Any) -> Any:
    """The engines' ``progress(message)``: a line on stderr (stdout stays the result, JSON or
    text) through the command's progress ``bar``."""
    return lambda msg: bar.say(f"  {msg}")


def _end(v: float | None) -> str:
    return "open (beyond the values profiled)" if v is None else f"{v:.6g}"


def _clean(x: Any) -> Any:
    """``x`` with non-finite floats as None (strict JSON)."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    return x


def _parse_span(span: str, fitted: dict[str, Any] | None, around: Any, names: list[str]) -> Any:
    """``--span``: one or two half-widths (A,B) in the parameters' units, or ``<k>se``: k
    standard errors of the fit given with ``--at``."""
    import numpy as np

    from skinkit.inverse.grid import GridError, span_from_se
    from skinkit.inverse.scaling import Scaling

    text = span.strip().lower()
    try:
        if text.endswith("se"):
            if fitted is None:
                raise GridError("--span in standard errors needs --at FIT.json")
            k = float(text[:-2])
            if not k > 0:
                raise ValueError
            sc = Scaling.for_parameters(around, names)
            return span_from_se(sc, np.array([around[p] for p in names]),
                                [fitted["se"].get(p) for p in names], k)
        half = [float(s) for s in text.split(",")]
        if len(half) not in (1, 2) or not all(h > 0 and math.isfinite(h) for h in half):
            raise ValueError
        return half
    except ValueError:
        raise GridError(f"--span {span!r}: give a positive number, two (A,B), or '<k>se'") from None


@click.command("grid")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.argument("session", type=click.Path(dir_okay=False))
@click.option("--pair", required=True, help="the two parameters of the grid, comma-separated (A,B)")
@click.option("--n", "n", type=click.IntRange(3, 201), default=11, show_default=True,
              help="grid points per parameter (n² forward solves)")
@click.option("--span", default=None,
              help="half-width about the centre: in scaled units (a fraction of the bounds' range; decades "
                   "for log-scaled parameters), one number or A_SPAN,B_SPAN; or '<k>se' (k standard errors "
                   "of the --at fit). Default: the bounds, else ±1 decade or ±50 %")
@click.option("--at", "at", type=click.Path(dir_okay=False), default=None,
              help="a skinkit fit result (fit.json): centre the grid there and draw its 95 % ellipses")
@click.option("--objective", "weighting", default="noise", show_default=True,
              help="weighting (as skinkit fit)")
@click.option("--holdout", default=None, help="protocols kept out (comma-separated)")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="directory for grid.json and grid.png (default: grid-<model>-<A>-<B>)")
@click.option("--overwrite", is_flag=True, help="replace grid.json and grid.png already in --out")
@click.option("--workers", type=click.IntRange(min=1), default=None, help="worker processes")
@click.option("--json", "as_json", is_flag=True, help="print the grid as JSON")
def grid(model_file: str, session: str, pair: str, n: int, span: str | None, at: str | None, weighting: str,
         holdout: str | None, out_dir: str | None, overwrite: bool, workers: int | None,
         as_json: bool) -> None:
    """The objective over a grid of two parameters of MODEL_FILE on SESSION, the others fixed (Fig 7-10)."""
    from skinkit.inverse import WEIGHTINGS
    from skinkit.inverse.grid import GridError, attach_covariance, objective_grid
    from skinkit.inverse.plots import grid_plot

    names = split_names(pair)
    if len(names) != 2:
        raise GridError(f"--pair {pair!r}: name exactly two parameters, as A,B")
    if names[0] == names[1]:
        raise GridError(f"--pair names {names[0]} twice; name two different parameters")
    if n < 3:
        raise GridError(f"--n must be at least 3 (a grid needs a centre and both sides), got {n}")
    if weighting not in WEIGHTINGS:
        raise SkinkitError(f"--objective {weighting!r}: must be one of {', '.join(WEIGHTINGS)}")
    fitted = _read_fit(at) if at else None
    model, obs = _session(model_file, session, holdout, workers)
    try:
        base = model.parameters()
        unknown = [p for p in names if p not in base]
        if unknown:
            raise GridError(f"--pair: the model has no parameter {', '.join(unknown)}; "
                            f"it has {', '.join(base.names)}")
        around = base
        if fitted is not None:
            around = base.with_values({k: v for k, v in fitted["values"].items() if k in base})
        half = None if span is None else _parse_span(span, fitted, around, names)
        out = Path(out_dir) if out_dir else Path.cwd() / f"grid-{model.name}-{names[0]}-{names[1]}"
        # before the grid runs
        check_result_files(out, ("grid.json", "grid.png"), "--out", overwrite=overwrite)
        with progress(stage="grid") as bar:
            say = _say(bar)
            say(f"{n} x {n} forward predictions of {model.name} on {session}")
            g = objective_grid(model, obs, (names[0], names[1]), n=n, span=half, weighting=weighting,
                               around=around, progress=say)
        if (fitted is not None and fitted["covariance"] is not None
                and all(p in fitted["names"] for p in names)):
            g = attach_covariance(g, fitted["names"], fitted["covariance"], fitted["values"],
                                  fitted["inflation"])
        g = _clean({**g, "session": str(session)})
        out.mkdir(parents=True, exist_ok=True)
        (out / "grid.json").write_text(jsonio.dumps(g, indent=1))
        png = grid_plot(g, out / "grid.png")
    finally:
        model.close()
    if as_json:
        click.echo(jsonio.dumps(g, indent=2))
        return
    a, b = names
    mn = g["minimum"]
    click.echo(f"{model.name} on {session}: objective over {a} x {b} ({n} x {n}, {g['wall_s']:.1f} s)")
    ua, ub = (unit_suffix(g["parameters"][k]["unit"]) for k in (a, b))
    click.echo(f"  lowest objective {mn['objective']:.6g} at {a} = {mn[a]:.6g}{ua}, {b} = {mn[b]:.6g}{ub}")
    if g["failed"]:
        click.echo(f"  {len(g['failed'])} grid point(s) could not be solved (grid.json: failed)")
    click.echo(f"wrote {out / 'grid.json'} and {png}")


@click.command("profile-likelihood")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.argument("session", type=click.Path(dir_okay=False))
@click.option("--parameter", "name", required=True, help="the parameter to profile")
@click.option("--free", default=None,
              help="the parameters re-fitted at each value (comma-separated; default: the model's free ones)")
@click.option("--n", "n", type=click.IntRange(3, 201), default=9, show_default=True,
              help="values profiled, over ±3 se (one fit each)")
@click.option("--values", "values", default=None, help="the values to profile instead [SI], comma-separated")
@click.option("--objective", "weighting", default="noise", show_default=True,
              help="weighting (as skinkit fit)")
@click.option("--holdout", default=None, help="protocols kept out (comma-separated)")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="directory for profile.json and profile.png (default: profile-<model>-<parameter>)")
@click.option("--overwrite", is_flag=True, help="replace profile.json and profile.png already in --out")
@click.option("--workers", type=click.IntRange(min=1), default=None, help="worker processes")
@click.option("--json", "as_json", is_flag=True, help="print the profile as JSON")
def profile(model_file: str, session: str, name: str, free: str | None, n: int, values: str | None,
            weighting: str, holdout: str | None, out_dir: str | None, overwrite: bool, workers: int | None,
            as_json: bool) -> None:
    """The profile likelihood of one parameter of MODEL_FILE on SESSION: the others re-fitted at each
    value; its 95 % interval beside the quadratic (Wald) one."""
    from skinkit.inverse import WEIGHTINGS
    from skinkit.inverse.grid import GridError, profile_likelihood
    from skinkit.inverse.plots import profile_plot

    if n < 3:
        raise GridError(f"--n must be at least 3, got {n}")
    if weighting not in WEIGHTINGS:
        raise SkinkitError(f"--objective {weighting!r}: must be one of {', '.join(WEIGHTINGS)}")
    vals = None
    if values is not None:
        try:
            vals = [float(v) for v in values.split(",") if v.strip()]
        except ValueError:
            raise GridError(f"--values {values!r}: give numbers in SI, comma-separated") from None
    model, obs = _session(model_file, session, holdout, workers)
    try:
        out = Path(out_dir) if out_dir else Path.cwd() / f"profile-{model.name}-{name}"
        # before it runs
        check_result_files(out, ("profile.json", "profile.png"), "--out", overwrite=overwrite)
        others = None if free is None else split_names(free)
        with progress(stage="profile likelihood") as bar:
            pr = profile_likelihood(model, obs, name, others, values=vals, n=n, weighting=weighting,
                                    progress=_say(bar))
        pr = _clean({**pr, "session": str(session)})
        out.mkdir(parents=True, exist_ok=True)
        (out / "profile.json").write_text(jsonio.dumps(pr, indent=1))
        png = profile_plot(pr, out / "profile.png")
    finally:
        model.close()
    if as_json:
        click.echo(jsonio.dumps(pr, indent=2))
        return
    unit = unit_suffix(pr["unit"])
    lo, hi = pr["interval"]
    click.echo(f"{model.name} on {session}: profile of {name} ({len(pr['values'])} values, re-fitted: "
               f"{', '.join(pr['free']) or 'none'}; {pr['n_forward']} forward solves, {pr['wall_s']:.1f} s)")
    click.echo(f"  estimate {pr['estimate']:.6g}{unit}; "
               f"95 % profile interval [{_end(lo)}, {_end(hi)}]{unit}")
    if pr["wald_interval"] is not None:
        w = pr["wald_interval"]
        click.echo(f"  quadratic (Wald) interval      [{w[0]:.6g}, {w[1]:.6g}]{unit} (± 1.96 se)")
    if pr["inflation"] > 1:
        click.echo(f"  both widened by chi2/dof = {pr['inflation']:.3g} "
                   "(the fit is worse than the noise explains)")
    click.echo(f"wrote {out / 'profile.json'} and {png}")
