"""``skinkit demo``: the main job on the embedded default (the virtual lab), end to end."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from skinkit import jsonio
from skinkit.cli._bench_out import page_option, write_page
from skinkit.units import unit_suffix


def _fmt(v: Any, unit: str) -> str:
    if v is None:
        return "-"
    if isinstance(v, str):
        return v
    return f"{v:.4g}{unit_suffix(unit)}".strip()


def closing_table(summary: dict[str, Any]) -> list[str]:
    """The closing table's lines: step, result, found, truth, error, time."""
    lines = [f"{'step':<9} {'result':<34} {'found':>14} {'truth':>14} {'error':>11} {'95 %':>5} {'time':>6}"]
    shown: set[str] = set()
    for r in summary["table"]:
        err = "-" if r["error"] is None else f"{r['error']:+.3g}{unit_suffix(r['error_unit'])}"
        t = "" if r["step"] in shown or r["time_s"] is None else f"{r['time_s']:.0f} s"
        shown.add(r["step"])
        inside = {True: "in", False: "out"}.get(r.get("within_95"), "")   # truth in the 95 % interval
        lines.append(f"{r['step']:<9} {r['result'][:34]:<34} {_fmt(r['found'], r['unit']):>14} "
                     f"{_fmt(r['truth'], r['unit']):>14} {err:>11} {inside:>5} {t:>6}")
    return lines


#: the diagnosis's per-sample and per-point arrays: kept in the summary and the gap report's
#: JSON (``gap/gap.json``), left off the results page, which carries figures
PER_SAMPLE = ("series", "points", "point_map_after")


def page_figures(summary: dict[str, Any]) -> dict[str, Any]:
    """The demo's summary for its results page: the diagnosis without :data:`PER_SAMPLE`."""
    diag = summary.get("diagnose")
    if not isinstance(diag, dict):
        return summary
    return {**summary, "diagnose": {k: v for k, v in diag.items() if k not in PER_SAMPLE}}


@click.command()
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=Path("demo-output"),
              show_default=True, help="Folder for the experiment file, truth file, reports and summary.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True,
              help="Seed of the virtual session (noise, speckle, board placements).")
@click.option("--quick", is_flag=True,
              help="Three protocols instead of four (normal, in-plane 0 and 90 deg): about three quarters "
                   "of the time.")
@click.option("--workers", type=click.IntRange(min=1, max=64), default=2, show_default=True,
              help="Worker processes of the finite-element model.")
@click.option("--shared-mesh", is_flag=True,
              help="Solve the truth on the model's own mesh and carry no model error (the inverse crime, "
                   "for comparison); by default the truth has a mesh of its own, ~10x the unknowns.")
@click.option("--extrapolated-truth", is_flag=True,
              help="Solve the truth on three meshes of its own (1, 2 and 3 times the model's element counts) "
                   "and use their limit at a vanishing element size: a truth closer to the skin's infinitely "
                   "fine one, at about four times the truth's solves.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@page_option
def demo(out_dir: Path, seed: int, quick: bool, workers: int, shared_mesh: bool, extrapolated_truth: bool,
         as_json: bool, page: Path | None) -> None:
    """Run the main job on a virtual-lab session whose truth is known: acquire (robot records,
    four rendered cameras, stochastic records) into one experiment file, identify the lumped
    models, calibrate-profile-track, identify the thesis's finite-element model, diagnose the
    sim-to-real gap, write the report; only then compare every step with the truth."""
    from skinkit.cli._paths import check_out_dir
    from skinkit.cli._progress import progress
    from skinkit.errors import SkinkitError
    from skinkit.pipelines.chain import missing_plugins, run_chain

    if shared_mesh and extrapolated_truth:
        raise click.BadParameter("cannot be combined with --shared-mesh (one truth mesh)",
                                 param_hint="--extrapolated-truth")
    missing = missing_plugins()
    if missing:
        raise SkinkitError(f"the demo needs plugins that are not installed: {', '.join(missing)} "
                           "(install skinkit-plugins: `make demo` does)")
    if out_dir.exists() and not out_dir.is_dir():
        raise SkinkitError(f"--out {out_dir}: exists and is not a folder")
    # a folder that cannot be made (under a file, on a read-only file system) is refused
    # naming --out before the chain starts, not by the first write minutes later
    check_out_dir(out_dir, "--out")
    # on stderr, also with --json: stdout carries only the summary
    with progress() as bar:
        summary = run_chain(out_dir, seed=seed, quick=quick, workers=workers,
                            progress=lambda step, f: _advance(bar, step, f),
                            mesh="shared" if shared_mesh else "extrapolated" if extrapolated_truth else "own")
    lines = _summary_lines(summary, out_dir)
    write_page(page, "The main job on the virtual lab", page_figures(summary), lines)
    if as_json:
        click.echo(jsonio.dumps(summary, indent=1, default=float))
        return
    for line in lines:
        click.echo(line)


def _advance(bar: Any, step: str, fraction: float) -> None:
    """One progress report of the chain: the gap's running messages are notes of one stage,
    of unknown fraction until done."""
    if step.startswith("gap:"):
        bar.update("gap", 1.0 if fraction >= 1.0 else None, step[4:].strip())
        return
    bar.update(step, fraction)


def _summary_lines(summary: dict[str, Any], out_dir: Path) -> list[str]:
    """What the demo prints: the files, the gap's messages, the closing table, the reports."""
    gap = summary["diagnose"]
    lines = [f"experiment file: {summary['experiment_file']}  (truth kept apart: {summary['truth_file']})"]
    lines += [f"gap: {m}" for m in gap.get("messages", [])]
    lines += ["", *closing_table(summary), "", f"report: {summary['report']}"]
    lines += [f"against the truth: {p}" for p in summary.get("plots", [])]
    lines += [f"gap report: {f}" for f in gap.get("files", [])]
    lines.append(f"summary: {out_dir / 'summary.json'}  (total {sum(summary['times_s'].values()):.0f} s)")
    return lines
