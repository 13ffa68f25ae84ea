"""``skinkit bench forward | fit | fit-invivo | coverage | mesh-nulls | mesh-error | diagnose | scar``:
the cost and the honesty of identification, beside the ways peers do it.

Each command runs :mod:`skinkit.bench`'s plain functions and prints their figures (JSON with
``--json``; a Markdown results page with ``--page``; progress on stderr); the benchmark modules
are imported only when a command runs.
"""

from __future__ import annotations

from pathlib import Path

import click

from skinkit.cli._bench_out import emit, page_option, write_page
from skinkit.cli._progress import progress
from skinkit.cli._scheduler import scheduler_callback

#: the coverage study's cases (kept here so that ``--help`` imports no benchmark)
COVERAGE_CASES = ("gel", "invivo", "twopad", "lumped")


@click.command("forward")
@click.option("--json", "as_json", is_flag=True, help="Print the figures as JSON.")
@click.option("--skip-invivo", is_flag=True, help="Only the parallel part (the in vivo part takes minutes).")
@page_option
def bench_forward(as_json: bool, skip_invivo: bool, page: Path | None) -> None:
    """Forward model: serial vs 2 workers vs Dask (identical, speed-up); the in vivo 0.1 Hz protocol."""
    from skinkit.bench import forward

    res = forward.run(skip_invivo)
    lines = forward.summary_lines(res)
    emit(res, as_json, lines)
    write_page(page, "Forward model: serial, worker processes and Dask", res, lines)


@click.command("fit")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True,
              help="noise seed of the virtual session")
@page_option
def bench_fit(as_json: bool, seed: int, page: Path | None) -> None:
    """Analytic-Jacobian fit vs finite differences vs derivative-free, same problem and start."""
    from skinkit.bench import fit

    res = fit.run(seed)
    lines = fit.summary_lines(res)
    emit(res, as_json, lines)
    write_page(page, "Fit: analytic Jacobian, finite differences, derivative-free", res, lines)


@click.command("fit-invivo")
@click.option("--protocols", "n_protocols", type=click.IntRange(1, 16), default=16, show_default=True,
              help="the first N of the 16 Table 12 protocols")
@click.option("--periods", type=click.IntRange(min=1), default=3, show_default=True)
@click.option("--workers", type=click.IntRange(min=1), default=2, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="print JSON")
@page_option
def bench_fit_invivo(n_protocols: int, periods: int, workers: int, as_json: bool, page: Path | None) -> None:
    """Four GOH + QLV parameters from the Table 12 protocols at in vivo scale: wall time, where it goes."""
    import sys

    from skinkit.bench import fit_invivo

    res = fit_invivo.run(n_protocols, periods, workers, log=sys.stderr)
    lines = fit_invivo.summary_lines(res)
    emit(res, as_json, lines)
    write_page(page, "Identification at in vivo scale", res, lines)


@click.command("coverage")
@click.option("--case", "case", type=click.Choice([*COVERAGE_CASES, "all"]), default="all", show_default=True,
              help="which truth")
@click.option("--seeds", type=click.IntRange(1), default=20, show_default=True,
              help="virtual sessions per case")
@click.option("--start", type=click.Choice(["perturbed", "truth"]), default="perturbed", show_default=True,
              help="each fit's start: the truth perturbed by ~20 % per parameter, or the truth")
@click.option("--first-seed", type=click.IntRange(0), default=0, show_default=True,
              help="seeds are first-seed, first-seed + 1, ...")
@click.option("--workers", type=click.IntRange(1), default=None, help="worker processes per FE prediction")
@click.option("--mesh", type=click.Choice(["shared", "own", "extrapolated"]), default="shared",
              show_default=True,
              help="finite-element truths on the model's mesh, on meshes of their own, or extrapolated to a "
                   "vanishing element size from three of their own (with own meshes every fit carries the "
                   "model's discretisation error)")
@click.option("--truth-factor", type=click.IntRange(2), default=None,
              help="with --mesh own: the truth's refinement over the model's mesh (element counts along "
                   "each in-plane axis times this, element layers times this + 1; default 2); with --mesh "
                   "extrapolated: the finest of the three meshes (every count times 1, 2, ..., this; "
                   "at least 3, the default)")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
@page_option
def bench_coverage(case: str, seeds: int, start: str, first_seed: int, workers: int | None, mesh: str,
                   truth_factor: int | None, as_json: bool, page: Path | None) -> None:
    """Coverage of the reported 95 % intervals over virtual sessions of known truth."""
    from skinkit.bench import coverage

    if truth_factor is not None and mesh == "shared":
        raise click.BadParameter("applies to truths on meshes of their own: add --mesh own or extrapolated",
                                 param_hint="--truth-factor")
    if mesh == "extrapolated" and truth_factor is not None and truth_factor < 3:
        raise click.BadParameter(f"with --mesh extrapolated the finest mesh is at least 3 times the model's "
                                 f"counts (three meshes 1, 2, 3 times), got {truth_factor}",
                                 param_hint="--truth-factor")
    truth_factor = truth_factor or (3 if mesh == "extrapolated" else 2)
    # progress goes to stderr, also with --json
    with progress(stage="bench coverage") as bar:
        res = coverage.run(case, seeds, start, first_seed, workers, say=bar.say, mesh=mesh,
                           truth_factor=truth_factor)
    lines = coverage.summary_lines(res)
    emit(res, as_json, lines, indent=1)
    write_page(page, "Coverage of the reported 95 % intervals", res, lines)


@click.command("mesh-nulls")
@click.option("--case", "cases", type=click.Choice(["disc-two-layers", "disc-gel", "all"]), default="all",
              show_default=True, help="which model")
@click.option("--seeds", type=click.IntRange(1), default=10, show_default=True, help="sessions per case")
@click.option("--first-seed", type=click.IntRange(0), default=0, show_default=True,
              help="seeds are first-seed, first-seed + 1, ...")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
@page_option
def bench_mesh_nulls(cases: str, seeds: int, first_seed: int, as_json: bool, page: Path | None) -> None:
    """Nulls with the mesh gap only: truths on meshes of their own, no effect; how often a cause is
    named with the model's discretisation error carried as noise, and without."""
    from skinkit.bench import mesh_nulls

    names = list(mesh_nulls.CASES) if cases == "all" else [cases]
    with progress(stage="bench mesh-nulls") as bar:
        res = mesh_nulls.run(names, seeds, first_seed, say=bar.say)
    lines = mesh_nulls.summary_lines(res)
    emit(res, as_json, lines, indent=1)
    write_page(page, "Nulls with the mesh gap only", res, lines)


@click.command("mesh-error")
@click.option("--case", "cases", type=click.Choice(["gel", "invivo", "twopad", "all"]), multiple=True,
              help="which finite-element truth (the coverage study's; repeat for several)  [default: gel]")
@click.option("--truth-factor", type=click.IntRange(2), default=2, show_default=True,
              help="the truth's refinement over the model's mesh (element counts along each in-plane "
                   "axis times this, element layers times this + 1)")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
@page_option
def bench_mesh_error(cases: tuple[str, ...], truth_factor: int, as_json: bool, page: Path | None) -> None:
    """How well the carried model error matches a truth on a mesh of its own: per channel the
    truth-minus-model error along the model's own refinement, and the excess per sample a
    noiseless null would show."""
    from skinkit.bench import mesh_error

    names = ["gel", "invivo", "twopad"] if "all" in cases else list(dict.fromkeys(cases or ["gel"]))
    with progress(stage="bench mesh-error") as bar:
        res = mesh_error.run(names, truth_factor, say=bar.say)
    lines = mesh_error.summary_lines(res)
    emit(res, as_json, lines, indent=1)
    write_page(page, "The carried model error against a truth of its own", res, lines)


@click.command("diagnose")
@click.option("--case", "cases", type=click.Choice(["forearm", "quick-case", "all"]), default="all",
              show_default=True, help="which virtual session")
@click.option("--shared-mesh", is_flag=True,
              help="the truth on the model's mesh and no model error carried (faster; the inverse crime)")
@click.option("--workers", type=click.IntRange(1), default=2, show_default=True, help="worker processes")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
@page_option
def bench_diagnose(cases: str, shared_mesh: bool, workers: int, as_json: bool, page: Path | None) -> None:
    """Where a finite-element gap diagnosis spends its time: per stage its seconds, its forward
    equivalents (whole-session predictions) and how each parameter's derivative was computed."""
    from skinkit.bench import diagnose_profile

    names = list(diagnose_profile.CASES) if cases == "all" else [cases]
    with progress(stage="bench diagnose") as bar:
        res = diagnose_profile.run(names, "shared" if shared_mesh else "own", workers, say=bar.say)
    lines = diagnose_profile.summary_lines(res)
    emit(res, as_json, lines, indent=1)
    write_page(page, "Where a gap diagnosis spends its time", res, lines)


@click.command("scar")
@click.option("--seeds", type=click.IntRange(0), default=10, show_default=True,
              help="sessions with a scar (seeds first-seed, first-seed + 1, ...)")
@click.option("--healthy", type=click.IntRange(0), default=10, show_default=True,
              help="healthy sessions (the same seeds, no scar)")
@click.option("--first-seed", type=click.IntRange(0), default=0, show_default=True, help="the first seed")
@click.option("--parallel", type=click.IntRange(1), default=1, show_default=True,
              help="cases run at once (worker processes; without --scheduler)")
@click.option("--scheduler", default=None, metavar="ADDRESS", callback=scheduler_callback,
              help="run the cases on this Dask scheduler (reached before any case starts)")
@click.option("--journal", type=click.Path(dir_okay=False), default=None,
              help="record each finished case in this file (JSON lines); a run with the same file "
                   "goes on where an earlier one stopped")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
@page_option
def bench_scar(seeds: int, healthy: int, first_seed: int, parallel: int, scheduler: str | None,
               journal: str | None, as_json: bool, page: Path | None) -> None:
    """Scar sessions: is a stiff elliptical scar between two pads named, is its centre found inside
    its outline and its stiffness ratio inside the 95 % interval; is nothing named on healthy skin."""
    from skinkit.bench import scar

    if seeds + healthy == 0:
        raise click.BadParameter("no case to run: give --seeds or --healthy above 0", param_hint="--seeds")
    with progress(stage="bench scar") as bar:
        res = scar.run(seeds, healthy, first_seed, parallel, scheduler, journal, say=bar.say)
    lines = scar.summary_lines(res)
    emit(res, as_json, lines, indent=1)
    write_page(page, "Scar sessions: finding a stiff scar between two pads", res, lines)
