"""``skinkit gap``: diagnose the sim-to-real gap of a calibrated model."""

from __future__ import annotations

from pathlib import Path

import click

from skinkit import jsonio
from skinkit.cli._paths import check_result_files, name_callback
from skinkit.cli._scheduler import scheduler_callback
from skinkit.cli._types import FiniteFloat
from skinkit.cli.registry import LazyGroup
from skinkit.errors import SkinkitError
from skinkit.forward.session import split_names

#: the diagnosis's benchmarks, imported only when one runs
GAP_COMMANDS: dict[str, str] = {
    "thesis-case": "skinkit.cli.gap_bench:thesis_case",
    "benchmark": "skinkit.cli.gap_bench:benchmark",
}


@click.group("gap", cls=LazyGroup, table=GAP_COMMANDS)
def gap() -> None:
    """Where a calibrated model misses a session, which unmodelled effect causes it, how far it shrinks."""


@gap.command("diagnose")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.argument("session", type=click.Path(dir_okay=False))
@click.option("--effects", default=None,
              help="candidate effects (comma-separated; default: every installed effect that applies)")
@click.option("--protocols", default=None,
              help="read only these records of SESSION (comma-separated; default all)")
@click.option("--holdout", default=None, help="protocols kept out of the fit and predicted (comma-separated)")
@click.option("--max-effects", type=click.IntRange(min=0), default=3, show_default=True,
              help="add at most this many effects, one per round (0: score and locate only)")
@click.option("--min-share", type=FiniteFloat(), default=0.5, show_default=True,
              help="the share of the excess residual an added effect must remove to be named a cause; "
                   "smaller significant improvements are reported as minor contributions")
@click.option("--max-iterations", type=click.IntRange(min=1), default=50, show_default=True,
              help="evaluations each fit may make (the calibration and every refit); a fit that stops "
                   "there is reported in the warnings")
@click.option("--noise", type=click.Choice(["auto", "white", "ar"]), default="auto", show_default=True,
              help="noise model of each record: auto (spikes left out; an autoregressive model of the "
                   "colour from the rest segment where BIC prefers it), white, or ar (required)")
@click.option("--candidates", type=click.IntRange(min=1), default=3, show_default=True,
              help="refit the model with this many top-scoring effects per round")
@click.option("--free", default=None, help="parameters to calibrate (comma-separated; default: the model's)")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="write gap.json (and gap.html) and model.toml (the calibrated model with the added "
                   "effects, at their fitted values) to this directory")
@click.option("--name", "gap_name", default=None, callback=name_callback("report name"),
              help="name of the report stored in an experiment-file SESSION (default: gap-<model name>)")
@click.option("--overwrite", is_flag=True,
              help="replace a report of that name already stored in SESSION, and gap.json/gap.html/"
                   "model.toml in --out")
@click.option("--workers", type=click.IntRange(min=1), default=None, help="worker processes (FE models)")
@click.option("--scheduler", default=None, metavar="ADDRESS", callback=scheduler_callback,
              help="a Dask scheduler address to solve the protocols on instead of --workers (FE models; "
                   "reached before any work starts)")
@click.option("--until", "until_s", type=FiniteFloat(min=0, min_open=True), default=None,
              help="diagnose only the session's first seconds [s] (e.g. the imaged part of a record)")
@click.option("--no-error-estimate", "no_error_estimate", is_flag=True,
              help="with --no-model-error: skip the discretisation check of a finite-element model (one "
                   "solve on a mesh refined 2x); without either a mesh error can be named as an effect")
@click.option("--model-error/--no-model-error", default=True, show_default=True,
              help="a finite-element model: estimate its mesh's discretisation error at the calibration "
                   "(a mesh refined 2x) and carry it as noise through every later step")
@click.option("--scan-grid", "scan_grid_mm", type=FiniteFloat(min=0, min_open=True), default=None,
              help="spacing [mm] of the centres a region effect (inclusion) is scanned at over the tracked "
                   "points (default: an eighth of their extent, at least their spacing)")
@click.option("--scan-sizes", default=None,
              help="sizes [mm] a region effect is scanned at (comma-separated radii; default: one and two "
                   "grid spacings)")
@click.option("--no-scan", is_flag=True,
              help="do not scan region effects: test them at their declared null position")
@click.option("--json", "as_json", is_flag=True, help="print the report as JSON")
def diagnose_cmd(model_file: str, session: str, effects: str | None, holdout: str | None, max_effects: int,
                 candidates: int, free: str | None, out_dir: str | None, gap_name: str | None,
                 overwrite: bool, workers: int | None, until_s: float | None, no_error_estimate: bool,
                 model_error: bool, as_json: bool, protocols: str | None, min_share: float, noise: str,
                 max_iterations: int, scan_grid_mm: float | None, scan_sizes: str | None,
                 no_scan: bool, scheduler: str | None) -> None:
    """Calibrate MODEL_FILE on SESSION (experiment file or CSV record), then say where the residual
    is above the noise, which installed effect explains it (score tests at every effect's null,
    then refits of the best), and how far the gap shrinks with it.

    An effect is added only when the gap is significant, its score test survives the
    correction for testing every effect, its refit lowers the AIC by more than 10 and does not
    worsen the held-out residual; for a finite-element model, also only when its score test
    survives with the mesh's discretisation error (the calibrated model solved on a mesh
    refined 2x) projected out. It is named a cause when it removes at least --min-share of the
    excess residual, else a minor contribution; what no effect explains is reported as such.
    Residuals are prewhitened by each record's noise model. An experiment-file SESSION stores
    the report (/gaps/<name>); --out receives gap.json and model.toml, the final model (MODEL_FILE
    with the added effects, every calibrated value and a [calibration] table of 95 % intervals).
    """
    from skinkit.cli._progress import progress
    from skinkit.forward import read_description
    from skinkit.gap.diagnose import diagnose, write_report

    stores = str(session).lower().endswith((".h5", ".hdf5"))
    if not 0 < min_share <= 1:
        raise SkinkitError(f"--min-share must be in (0, 1], got {min_share:g}")
    if not Path(model_file).is_file():
        raise SkinkitError(f"model file {model_file}: not found")
    if not Path(session).is_file():
        raise SkinkitError(f"session {session}: not found")
    spec = read_description(model_file)
    model_name = dict(spec.get('model', {}) or {}).get('name', Path(model_file).stem)
    name = gap_name if gap_name is not None else f"gap-{model_name}"
    if stores and not overwrite:   # before the diagnosis runs, not after it
        from skinkit.store import open_experiment
        with open_experiment(session) as exp:
            if name in exp.gap_names():
                raise SkinkitError(f"{session} already holds a gap report named {name!r}: give another "
                                   "--name, or --overwrite to replace it")
    if out_dir:   # an earlier report in --out is not replaced silently either
        check_result_files(out_dir, ("gap.json", "gap.html", "model.toml"), "--out", overwrite=overwrite)

    if no_scan and (scan_grid_mm is not None or scan_sizes is not None):
        raise SkinkitError("--no-scan: cannot be given with --scan-grid or --scan-sizes")
    from skinkit.gap.scan_step import scan_options
    scan = scan_options(scan_grid_mm, None if scan_sizes is None else split_names(scan_sizes), not no_scan)
    wanted = split_names(effects) if effects is not None else None
    if effects is not None and not wanted:
        raise SkinkitError("--effects: no effect named")
    with progress(stage="gap diagnose") as bar:
        report = diagnose(model_file, session, effects=wanted, holdout=split_names(holdout),
                          protocols=split_names(protocols) or None,
                          free=None if free is None else split_names(free), max_effects=max_effects,
                          candidates=candidates, workers=workers, scheduler=scheduler, until=until_s,
                          progress=lambda line: bar.say(f"  {line}"),
                          error_estimate=not no_error_estimate, min_share=min_share, noise=noise,
                          max_iterations=max_iterations, model_error=model_error, scan=scan)
    if stores:
        from skinkit.store import open_experiment
        with open_experiment(session, "a") as exp:
            exp.write_gap(name, report)
    written = write_report(report, out_dir) if out_dir else []
    if out_dir:
        from skinkit.gap.calibrated import write_model
        written.append(write_model(report, model_file, out_dir, workers=workers))
    if out_dir and not any(str(p).endswith(".html") for p in written):
        click.echo("  note: skinkit.gap.html is not installed: no gap.html written", err=True)
    d = report.to_dict()
    if stores:
        d["stored_as"] = name
    if as_json:
        click.echo(jsonio.dumps(d, indent=2, allow_nan=False))
        return
    _print(d, written)


def _print(d: dict, written: list) -> None:
    fit = d["fit"]
    click.echo(f"{d['model']} on {d['session']}: calibrated χ²/ν {fit['chi2_per_dof']:.4g} "
               f"({', '.join(f'{k} = {v:.4g}' for k, v in fit['parameters'].items())})")
    for m in d.get("messages", []):
        click.echo(m)
    cands = d["candidates"]
    if cands:
        click.echo("candidates (score test at the null, then refit):")
        for c in cands:
            refit = (f"ΔAIC {c['delta_aic']:.1f}, share {100 * c['share']:.0f} %"
                     if c["refitted"] and c["delta_aic"] is not None and c.get("share") is not None
                     else "refitted" if c["refitted"] else "not refitted")
            others = c["not_separable_from"]
            sep = f"; not separable from {', '.join(others)}" if others else ""
            click.echo(f"  {c['effect']:20s} {c.get('role', ''):9s} LM {c['score']:10.4g} (q {c['dof']}) "
                       f"p {c['p_value']:.3g}  {refit}{sep}")
    if d.get("stored_as"):
        click.echo(f"stored as /gaps/{d['stored_as']} in {d['session']}")
    for p in written:
        click.echo(f"wrote {p}")
