"""``skinkit demo``: the main job on the embedded default (the virtual lab)."""

from __future__ import annotations

import json
from pathlib import Path

import click


@click.command()
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=Path("demo-output"),
              show_default=True, help="Folder for the experiment file, plots and summary.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the virtual session.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def demo(out_dir: Path, seed: int, as_json: bool) -> None:
    """Run every pipeline step that exists on a virtual-lab session whose truth is known:
    simulate, stream into an experiment file, identify lumped models, compare with the truth."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from skinkit.pipelines.demo import run_demo

    with Progress(TextColumn("{task.description:<28}"), BarColumn(), TimeElapsedColumn(),
                  disable=as_json) as bar:
        tasks: dict[str, int] = {}

        def progress(step: str, fraction: float) -> None:
            if step not in tasks:
                tasks[step] = bar.add_task(step, total=1.0)
            bar.update(tasks[step], completed=fraction)

        summary = run_demo(out_dir, seed=seed, progress=progress)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    click.echo(f"experiment file: {summary['experiment_file']}")
    for rec in summary["store"]["records"]:
        click.echo(f"  record {rec['protocol']!r}: {rec['samples']} samples at {rec['rate_hz']:.0f} Hz, "
                   f"channels {', '.join(rec['channels'])}, complete={rec['complete']}")
    t, lin, wie = summary["truth"], summary["linear"], summary["wiener"]
    le, we = summary["linear_error_pct"], summary["wiener_error_pct"]
    click.echo("linear skin (robot's mass removed)      identified        truth       error")
    click.echo(f"  K [N/m]   {lin['K_N_per_m']:>30.5g} {t['K_N_per_m']:>12.5g} {le['K']:>+10.2f} %")
    click.echo(f"  B [N s/m] {lin['B_Ns_per_m']:>30.5g} {t['B_Ns_per_m']:>12.5g} {le['B']:>+10.2f} %")
    click.echo(f"  I [g]     {lin['I_kg'] * 1e3:>30.5g} {t['I_kg'] * 1e3:>12.5g} {le['I']:>+10.2f} %")
    click.echo(f"  VAF {lin['vaf_linear_pct']:.2f} %")
    click.echo("Wiener skin")
    click.echo(f"  C1 [mm]   {wie['C1_m'] * 1e3:>30.5g} {t['C1_m'] * 1e3:>12.5g} {we['C1']:>+10.2f} %")
    click.echo(f"  C2 [1/N]  {wie['C2_per_N']:>30.5g} {t['C2_per_N']:>12.5g} {we['C2']:>+10.2f} %")
    click.echo(f"  VAF Wiener {wie['vaf_wiener_pct']:.2f} % vs linear {wie['vaf_linear_pct']:.2f} %")
    for w in lin["warnings"] + wie["warnings"]:
        click.echo(f"  warning: {w}")
    rob = summary["robot"]
    if "skipped" in rob:
        click.echo(f"robot: skipped ({rob['skipped']})")
    else:
        click.echo(f"robot (sim driver): {rob['protocol']} {rob['simulated_s']:.0f} s simulated in "
                   f"{rob['wall_s']:.0f} s, {rob['samples']} samples, {rob['lost']} lost; normal travel "
                   f"{rob['tip_travel_pp_m'][2] * 1e3:.3f} mm p-p, "
                   f"peak force {rob['peak_normal_force_N']:.2f} N")
    fem = summary["fem"]
    if "skipped" in fem:
        click.echo(f"finite elements: skipped ({fem['skipped']})")
    else:
        w, wo = fem["with_prestretch"], fem["without_prestretch"]
        click.echo(f"finite elements: in vivo model, {w['dof']} unknowns, 20 mN tip force: indentation "
                   f"{-w['tip_displacement_m'][2] * 1e6:.1f} um with the skin's pre-stretch, "
                   f"{-wo['tip_displacement_m'][2] * 1e6:.1f} um without")
        click.echo(f"  ParaView: {w['paraview']}")
    vis = summary["vision"]
    if "skipped" in vis:
        click.echo(f"stereo vision: skipped ({vis['skipped']})")
    else:
        click.echo(f"stereo vision: rig calibrated to {vis['reprojection_rms_px']:.3f} px; automatic "
                   f"profile of {vis['profile_points']} points (mean ISU {vis['mean_isu_px']:.2f} px)")
        click.echo(f"  profile vs truth: {vis['profile_error_um']['rms']:.1f} um RMS, "
                   f"{vis['profile_error_um']['max']:.1f} um max")
        click.echo(f"  3D tracks vs truth: {vis['track_error_um']['rms']:.1f} um RMS, "
                   f"{vis['track_error_um']['max']:.1f} um max "
                   f"({100 * vis['tracked_fraction']:.0f} % tracked)")
    for p in summary["plots"] + vis.get("plots", []):
        click.echo(f"plot: {p}")
    click.echo(f"summary: {out_dir / 'summary.json'}")
