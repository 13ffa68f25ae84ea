"""``skinkit select``: AIC, AICc and held-out error over subsets of free parameters."""

from __future__ import annotations

import click

from skinkit import jsonio
from skinkit.errors import SkinkitError
from skinkit.forward.session import read_session


@click.command("select")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.argument("session", type=click.Path(dir_okay=False))
@click.option("--subsets", required=True,
              help="free-parameter subsets, parameters comma-separated, subsets "
                   "semicolon-separated: 'a,b;a,b,c'")
@click.option("--objective", "weighting", default="noise", show_default=True,
              help="weighting: noise, unweighted, displacement, threshold, robot-only, strain")
@click.option("--holdout", default=None,
              help="protocols kept out of every fit and predicted (comma-separated)")
@click.option("--folds", default="protocol", show_default=True,
              help="protocol: k-fold by protocol over the fitted protocols; none: no folds")
@click.option("--rank-by", type=click.Choice(["aicc", "aic", "kfold"]), default="aicc", show_default=True,
              help="the column that ranks the subsets")
@click.option("--segments", type=click.Choice(["cycles"]), default=None,
              help="split every record into protocols first (cycles: one per loading cycle), "
                   "so that the folds and --holdout can be cycles")
@click.option("--workers", type=click.IntRange(min=1), default=None, help="worker processes")
@click.option("--json", "as_json", is_flag=True, help="print the table as JSON")
def select(model_file: str, session: str, subsets: str, weighting: str, holdout: str | None, folds: str,
           rank_by: str, segments: str | None, workers: int | None, as_json: bool) -> None:
    """Fit MODEL_FILE to SESSION with each subset of free parameters; rank by AIC (thesis
    Eq 7.14) and AICc beside the held-out error (k-fold by protocol, and --holdout)."""
    from skinkit.cli._progress import progress
    from skinkit.forward import load
    from skinkit.inverse import WEIGHTINGS
    from skinkit.inverse.selection import check_subsets, format_table, parse_subsets
    from skinkit.inverse.selection import select as run_select

    if weighting not in WEIGHTINGS:
        raise SkinkitError(f"--objective {weighting!r}: must be one of {', '.join(WEIGHTINGS)}")
    fold = folds.strip().lower()
    if fold not in ("protocol", "none"):
        raise SkinkitError(f"--folds {folds!r}: must be 'protocol' or 'none'")
    wanted = parse_subsets(subsets)
    model = load(model_file, workers=workers)
    try:
        check_subsets(model.parameters(), wanted)   # before the session is read
        obs = read_session(model, session, holdout, segments)

        with progress(stage="select") as bar:   # on stderr, also with --json
            res = run_select(model, obs, wanted, weighting, None if fold == "none" else fold, rank_by=rank_by,
                             progress=lambda m: bar.say(f"  {m}"))
    finally:
        model.close()
    res["session"] = str(session)
    if as_json:
        click.echo(jsonio.dumps(res, indent=2, default=float))
        return
    click.echo(f"{res['model']} on {session}: {len(res['fitted_protocols'])} fitted protocol(s), "
               f"{weighting} weighting; ranked by {rank_by}")
    for line in format_table(res):
        click.echo(line)
    best = res["rows"][0]
    click.echo(f"best: {','.join(best['free'])} (Akaike weight {best['weight_aicc']:.2f} by AICc)")
    for row in res["rows"]:
        for msg in row["problems"]:
            click.echo(f"  ! [{','.join(row['free'])}] {msg}")
