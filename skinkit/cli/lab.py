"""``skinkit lab``: the virtual lab — sessions made by a truth model, the truth kept apart."""

from __future__ import annotations

import click

from skinkit.cli._paths import check_out_file
from skinkit.cli.registry import LazyGroup


@click.group("lab", cls=LazyGroup)
def lab() -> None:
    """The virtual lab: synthetic sessions whose truth is known."""


@lab.command("session")
@click.argument("truth", type=click.Path(dir_okay=False))
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False),
              help="the session file to write (experiment file, laid out like a real one)")
@click.option("--truth-out", "truth_out", required=True, type=click.Path(dir_okay=False),
              help="the truth file to write (JSON: model after effects, parameters, seed, noise)")
@click.option("--seed", required=True, type=click.IntRange(min=0), help="seed of every random draw")
@click.option("--protocols", default=None,
              help="library protocols, comma-separated (default: the model's [session] protocols, "
                   "else normal_indentation,in_plane_000,in_plane_090,out_of_plane_330 for FE truths)")
@click.option("--noise-scale", "noise_scale", default="1", show_default=True,
              help="multiply every instrument imperfection (noise, resolution, offset) by this (> 0)")
@click.option("--images", is_flag=True, help="render four-camera images and track them (not available yet)")
@click.option("--shared-mesh", is_flag=True,
              help="solve a finite-element truth on its model file's own mesh, the model's (default: on "
                   "a mesh of its own, 2x finer in-plane, 3x through the thickness, its own node "
                   "placement; the truth file states both meshes and the truth's error)")
@click.option("--extrapolated-truth", is_flag=True,
              help="solve a finite-element truth on three meshes of its own (every element count 1, 2 and "
                   "3 times the model's, its own node placement) and record their limit at a vanishing "
                   "element size (Richardson, with the observed order; its estimated error in the truth "
                   "file)")
def session(truth: str, out: str, truth_out: str, seed: int, protocols: str | None, noise_scale: str,
            images: bool, shared_mesh: bool, extrapolated_truth: bool) -> None:
    """Run the TRUTH model file (effects included) through the protocols and record it as a session."""
    from skinkit.cli._progress import progress
    from skinkit.forward import read_description
    from skinkit.lab.session import check_noise_scale, check_options, make_session

    if shared_mesh and extrapolated_truth:
        raise click.BadParameter("cannot be combined with --shared-mesh (one truth mesh)",
                                 param_hint="--extrapolated-truth")
    scale = check_noise_scale(noise_scale)
    check_options(out, truth_out, protocols, scale, images)
    # the session is written beside --out under a hidden name: a folder that takes no file is
    # refused here, naming the path given, before the truth runs
    check_out_file(out, "--out")
    check_out_file(truth_out, "--truth-out")
    read_description(truth)  # a missing or malformed model file: one line, before any progress bar
    with progress(transient=True, width=24) as bar:
        doc = make_session(truth, out, truth_out, seed, protocols=protocols, noise_scale=scale,
                           images=images, progress=bar,
                           mesh="shared" if shared_mesh else "extrapolated" if extrapolated_truth else "own")
    names = ", ".join(f"{p['name']} ({p['samples']} samples, {p['frames']} frames)" for p in doc["protocols"])
    click.echo(f"session {out}: {names}")
    click.echo(f"truth {truth_out}: {doc['kind']} model, {len(doc['parameters'])} parameters, "
               f"{len(doc['effects'])} effect(s), seed {doc['seed']}, noise scale {doc['noise_scale']:g}")
    mesh = doc.get("mesh")
    if mesh:
        click.echo(f"truth mesh: {mesh['mode']}, {mesh['truth_unknowns']:,} unknowns "
                   f"({mesh['truth_elements']:,} elements); the model file's {mesh['model_unknowns']:,} "
                   f"({mesh['model_elements']:,})")
        ext = mesh.get("extrapolation")
        if ext:
            click.echo(f"  extrapolated from {', '.join(f'{u:,}' for u in ext['member_unknowns'])} unknowns")
            kept = [k for k, o in ext["orders"].items() if not o.get("extrapolated", True)]
            if kept:
                click.echo(f"  not in the asymptotic range, the finest mesh kept: {', '.join(kept)}")
        for c, row in (mesh.get("discretisation") or {}).items():
            click.echo(f"  {c}: truth's own error {'estimated at' if ext else 'at most'} "
                       f"{row['truth_over_noise']:.3g} noise levels RMS; the model's mesh about "
                       f"{row['model_over_noise']:.3g}")


@lab.command("scar-session")
@click.option("--seed", required=True, type=click.IntRange(min=0),
              help="seed of every random draw: the scar (ratio, size, angle, position) and the noise")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False),
              help="the session file to write (experiment file, recorded like the real two-pad record)")
@click.option("--truth-out", "truth_out", required=True, type=click.Path(dir_okay=False),
              help="the truth file to write (JSON: the scar and its outline, the truth model, the noise)")
@click.option("--healthy", is_flag=True,
              help="no scar: the same geometry, protocol and noise draws (a null session)")
@click.option("--shared-mesh", is_flag=True,
              help="solve the truth on the model file's own mesh (default: on a mesh of its own, 2x finer "
                   "in-plane, 3x through the thickness)")
def scar_session(seed: int, out: str, truth_out: str, healthy: bool, shared_mesh: bool) -> None:
    """A two-pad extension session whose truth has a stiff elliptical scar between the pads.

    The model is the coarse two-pad example extension_twopad_scar.toml; the scar's stiffness ratio
    (2 to 10), diameters (4 to 12 mm), angle and position (inside the pads' gap band) are drawn from
    SEED. Force, pad displacement and 2D tracks are recorded at the noise levels of the real healthy
    two-pad record. The scar's outline is in the truth file only.
    """
    from skinkit.cli._progress import progress
    from skinkit.lab.scar import make_scar_session
    from skinkit.lab.session import check_options

    check_options(out, truth_out)
    check_out_file(out, "--out")
    check_out_file(truth_out, "--truth-out")
    with progress(transient=True, width=24) as bar:
        doc = make_scar_session(out, truth_out, seed, healthy=healthy, progress=bar,
                                mesh="shared" if shared_mesh else "own")
    p = doc["protocols"][0]
    click.echo(f"session {out}: {p['name']} ({p['samples']} samples, {p['frames']} frames, "
               f"{p['points']} points)")
    # the scar itself is not printed: whoever diagnoses the session should not see it
    what = "healthy (no scar)" if doc.get("scar") is None else "a scar (its outline in this file only)"
    click.echo(f"truth {truth_out}: {what}, seed {doc['seed']}")
    mesh = doc.get("mesh") or {}
    if mesh:
        click.echo(f"truth mesh: {mesh['mode']}, {mesh['truth_unknowns']:,} unknowns; the model file's "
                   f"{mesh['model_unknowns']:,}")
