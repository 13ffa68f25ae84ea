"""``skinkit design``: which protocol of the library would best pin down the current fit."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from skinkit import jsonio
from skinkit.errors import SkinkitError
from skinkit.forward.session import read_session, split_names


def read_fit(path: str) -> tuple[dict[str, float], list[str]]:
    """Values and free names of a ``skinkit fit --out`` ``fit.json``; one-line errors."""
    p = Path(path)
    if p.is_dir():
        p = p / "fit.json"
    try:
        doc: Any = json.loads(p.read_text())
    except FileNotFoundError:
        raise SkinkitError(f"--at {path}: no such file (a fit.json written by skinkit fit --out)") from None
    except (OSError, ValueError) as exc:
        raise SkinkitError(f"--at {path}: not a readable JSON fit ({exc})") from None
    pars = doc.get("parameters") if isinstance(doc, dict) else None
    if not isinstance(pars, dict) or not all(isinstance(v, dict) and "value" in v for v in pars.values()):
        raise SkinkitError(f"--at {path}: has no 'parameters' table of values "
                           "(is it a fit.json of skinkit fit?)")
    values = {k: float(v["value"]) for k, v in pars.items()}
    free = [k for k, v in pars.items() if v.get("free")]
    return values, free


@click.command("design")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.argument("session", type=click.Path(dir_okay=False))
@click.option("--free", default=None,
              help="parameters to pin down (comma-separated; default: the free ones of --at, "
                   "else the model's)")
@click.option("--at", "at", default=None,
              help="a fit.json of skinkit fit --out (or its directory): linearise there "
                   "(default: the model's values)")
@click.option("--candidates", default=None,
              help="library protocols to rank (comma-separated; default: every protocol that "
                   "drives the model)")
@click.option("--holdout", default=None, help="protocols of SESSION left out of the current information")
@click.option("--workers", type=click.IntRange(min=1), default=None, help="worker processes")
@click.option("--json", "as_json", is_flag=True, help="print the ranking as JSON")
def design(model_file: str, session: str, free: str | None, at: str | None, candidates: str | None,
           holdout: str | None, workers: int | None, as_json: bool) -> None:
    """Rank protocols of the library by the gain in log det of the Fisher information they
    would add to SESSION's fit of MODEL_FILE (D-optimality), and say what each pins down."""
    from skinkit.cli._progress import progress
    from skinkit.forward import load
    from skinkit.inverse.design import format_ranking, parse_candidates, rank_protocols

    values, fit_free = read_fit(at) if at else ({}, [])
    cands = parse_candidates(candidates)
    model = load(model_file, workers=workers)
    try:
        known = set(model.parameters().names)
        unknown = sorted(set(values) - known)
        if unknown:
            raise SkinkitError(f"--at {at}: parameters {', '.join(unknown)} are not the model's "
                               f"(a fit of another model?)")
        names = split_names(free) if free is not None else fit_free or None
        obs = read_session(model, session, holdout)

        with progress(stage="design") as bar:   # on stderr, also with --json
            res = rank_protocols(model, obs, values or None, names, cands,
                                 progress=lambda m: bar.say(f"  {m}"))
    finally:
        model.close()
    res["session"] = str(session)
    if as_json:
        click.echo(jsonio.dumps(res, indent=2, default=float))
        return
    click.echo(f"{res['model']} on {session}: candidates ranked by the gain in log det of the "
               "Fisher information")
    for line in format_ranking(res):
        click.echo(line)
