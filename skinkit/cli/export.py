"""``skinkit export``: a model in another solver's input format (``export febio``)."""

from __future__ import annotations

import click

from skinkit.cli._paths import check_out_file, staged_file
from skinkit.cli.registry import LazyGroup
from skinkit.errors import SkinkitError


@click.group("export", cls=LazyGroup)
def export() -> None:
    """Write a model in another solver's input format."""


@export.command("febio")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.option("--session", default=None, type=click.Path(dir_okay=False),
              help="drive the indenter by this session's recorded tip position or force")
@click.option("--protocol", default=None,
              help="the session's protocol to export (needed when it has several)")
@click.option("--out", "out_file", required=True, type=click.Path(dir_okay=False),
              help="the FEBio model file to write (.feb)")
@click.option("--overwrite", is_flag=True, help="replace an existing --out file")
@click.option("--strict", is_flag=True,
              help="refuse a feature whose nearest FEBio counterpart differs (default: export it, "
                   "with a warning naming the difference)")
def febio(model_file: str, session: str | None, protocol: str | None, out_file: str,
          overwrite: bool, strict: bool) -> None:
    """Write MODEL_FILE (a finite-element model) as an FEBio model (spec 4.0; mm, N, s, MPa).

    The mesh (hex27), the layers' materials, the fixed sets, the rigid indenter and its load
    curves: the model file's [load], or with --session the recorded drive of one protocol.
    A feature FEBio has no counterpart of is refused, naming it; one whose nearest counterpart
    differs in a known way is exported with a warning naming the difference (--strict: refused).
    """
    from skinkit.export.febio import febio_model, write_feb

    out = check_out_file(out_file, "--out")   # before any work: an earlier file is never replaced silently
    if (out.exists() or out.is_symlink()) and not overwrite:
        raise SkinkitError(f"--out {out}: already exists; give another --out, or --overwrite to replace it")
    if protocol is not None and session is None:
        raise SkinkitError("--protocol: needs --session (the protocol is one of the session's)")
    tree, summary = febio_model(model_file, session=session, protocol=protocol, strict=strict)
    with staged_file(out) as tmp:
        write_feb(tree, tmp)
    for note in summary["approximations"]:
        click.echo(f"warning: {note}", err=True)
    if summary["inverted_at_gauss_points"]:
        # the quadratic map of a strongly curved or graded element can fold near a corner: skinkit's
        # mesh as it is, which FEBio refuses at its first step ("negative jacobian")
        click.echo(f"warning: {summary['inverted_at_gauss_points']} element(s) have a non-positive "
                   "Jacobian at a Gauss point (the model file's mesh); FEBio will refuse them -- "
                   "refine or ungrade the mesh", err=True)
    drive = summary["drive"]
    how = "no drive" if drive is None else (f"{drive['mode']} drive from {drive['source']}, "
                                            f"{drive['steps']} steps over {drive['duration']:g} s")
    click.echo(f"FEBio {summary['spec']} model {out}: {summary['elements']} hex27 elements, "
               f"{summary['nodes']} nodes, materials {', '.join(summary['materials'])}; {how}; "
               f"units {summary['units']}")
