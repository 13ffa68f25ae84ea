"""``skinkit gap benchmark`` and ``skinkit gap thesis-case``: the diagnosis's benchmarks."""

from __future__ import annotations

import math
from pathlib import Path

import click

from skinkit import jsonio
from skinkit.cli._bench_out import page_option, write_page
from skinkit.cli._progress import progress
from skinkit.cli._scheduler import scheduler_callback


def _names(text: str | None, option: str = "--effects") -> list[str] | None:
    from skinkit.bench.gap_cases import BenchmarkError

    if text is None:
        return None
    out = [s.strip() for s in text.split(",") if s.strip()]
    if not out:
        raise BenchmarkError(f"{option}: nothing named")
    return out


@click.command("benchmark")
@click.option("--quick", is_flag=True, help="the quick run (a handful of effects at moderate magnitude, "
              "two null sessions; measured time in docs/guide/gap-benchmark.md)")
@click.option("--scheduler", default=None, metavar="ADDRESS", callback=scheduler_callback,
              help="run the cases on this Dask scheduler (reached before any work starts)")
@click.option("--json", "as_json", is_flag=True, help="print JSON (progress lines go to stderr)")
@click.option("--seeds", type=click.IntRange(1), default=None, help="seeds per effect and magnitude "
              "(default 1 quick, 3 full)")
@click.option("--effects", default=None, metavar="NAME,...", help="only these effects in the truths")
@click.option("--model", default=None,
              help="preset (quick: coarse in vivo, the default; lumped: extension-relaxation) "
              "or a model file")
@click.option("--nulls", type=click.IntRange(0), default=None,
              help="null sessions (default 2 quick, 20 full)")
@click.option("--parallel", type=click.IntRange(1), default=2, show_default=True,
              help="cases run at once (worker processes; without --scheduler)")
@click.option("--journal", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="record each finished case in FILE (JSON lines) and skip the cases it already "
              "holds: resume a stopped run, or add seeds or null sessions to a finished one")
@click.option("--recorded-only", is_flag=True, help="run nothing: score the cases the --journal holds "
              "(a run under way or stopped)")
@click.option("--alternative", is_flag=True, help="truths written apart from the effect plugins (other "
              "forms of the effects, coloured and spiky noise, artefacts no effect describes) on the lumped "
              "extension model; see 'Outside its own forms' in docs/guide/gap-benchmark.md")
@click.option("--forms", default=None, metavar="NAME,...", help="with --alternative: only these truth forms")
@click.option("--shared-mesh", is_flag=True, help="solve each finite-element truth on the model's own mesh "
              "(the inverse crime, for comparison; by default a truth has a finer mesh of its own and the "
              "diagnosis carries the model's discretisation error)")
@page_option
def benchmark(quick: bool, scheduler: str | None, as_json: bool, seeds: int | None, effects: str | None,
              model: str | None, nulls: int | None, parallel: int, journal: str | None, recorded_only: bool,
              alternative: bool, forms: str | None, shared_mesh: bool, page: Path | None) -> None:
    """Withheld-effect benchmark: diagnose virtual sessions whose truth has an effect the model lacks."""
    from skinkit.cli.bench import _no_solve_cache
    _no_solve_cache()
    from skinkit.bench.gap_benchmark import run as benchmark_run
    from skinkit.bench.gap_benchmark import summary_lines
    from skinkit.bench.gap_cases import BenchmarkError

    if alternative:
        if shared_mesh:
            raise BenchmarkError("--shared-mesh: the alternative truths' base response is the model's own "
                                 "(their forms are put on its force), so there is no other mesh to leave")
        _alternative(quick, scheduler, as_json, seeds, parallel, journal, recorded_only, forms, page,
                     effects=effects, model=model, nulls=nulls)
        return
    if forms is not None:
        raise BenchmarkError("--forms chooses the truths of --alternative: add --alternative, "
                             "or use --effects")
    with progress(stage="gap benchmark") as bar:
        res = benchmark_run(quick, scheduler=scheduler, seeds=seeds, progress=bar.say,
                            model=model or "quick", effects=_names(effects), nulls=nulls, parallel=parallel,
                            journal=journal, recorded_only=recorded_only,
                            mesh="shared" if shared_mesh else "own")
    lines = summary_lines(res)
    write_page(page, "Withheld-effect benchmark of the gap diagnosis", res, lines)
    if as_json:
        click.echo(jsonio.dumps(res, indent=1, default=float))
        return
    for line in lines:
        click.echo(line)


def _alternative(quick: bool, scheduler: str | None, as_json: bool, seeds: int | None, parallel: int,
                 journal: str | None, recorded_only: bool, forms: str | None, page: Path | None, *,
                 effects: str | None, model: str | None, nulls: int | None) -> None:
    """``--alternative``: the options that choose the withheld-effect benchmark's truths are refused."""
    from skinkit.bench.gap_alternative import PRESETS, run, summary_lines
    from skinkit.bench.gap_cases import BenchmarkError

    preset = "lumped" if model is None else model
    if preset not in PRESETS:
        raise BenchmarkError(f"--alternative --model: its truths are written for the presets "
                             f"{', '.join(PRESETS)} (lumped: the extension model, the default; quick: the "
                             f"quick finite-element model), got {model!r}")
    if effects is not None:
        raise BenchmarkError("--alternative: --effects chooses plugin truths; choose its truths with --forms")
    if nulls is not None:
        raise BenchmarkError("--alternative: its null sessions are the null forms (white, AR(1), spikes) at "
                             "--seeds seeds each; leave out --nulls")
    with progress(stage="gap benchmark --alternative") as bar:
        res = run(quick, seeds=seeds, forms_=_names(forms, "--forms"), parallel=parallel, scheduler=scheduler,
                  journal=journal, recorded_only=recorded_only, progress=bar.say, preset=preset)
    lines = summary_lines(res)
    write_page(page, "The gap diagnosis on truths it did not make", res, lines)
    if as_json:
        click.echo(jsonio.dumps(res, indent=1, default=float))
        return
    for line in lines:
        click.echo(line)


@click.command("thesis-case")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="noise seed")
@click.option("--workers", type=click.IntRange(min=1), default=2, show_default=True, help="worker processes")
@click.option("--json", "as_json", is_flag=True, help="print JSON (the whole report under 'report')")
@page_option
def thesis_case(seed: int, workers: int, as_json: bool, page: Path | None) -> None:
    """The thesis's case: pre-stress withheld from a GOH + QLV model of a virtual forearm session."""
    from skinkit.bench.gap_thesis_case import run as thesis_case_run

    with progress(stage="gap thesis-case") as bar:
        res = thesis_case_run(seed, workers, progress=lambda m: bar.say(f"  {m}"))
    lines = list(res["report"].get("messages", []))
    if "prestress" in res:
        p, e = res["prestress"], res["prestress_error"]
        lines.append(f"prestress identified: λ1 {p['l1']:.4f} (truth 1.10), λ2 {p['l2']:.4f} (1.03), "
                     f"θ {math.degrees(p['angle']):.2f}° (20°); θ error {e['angle_deg']:+.2f}°")
    write_page(page, "The thesis's case: pre-stress withheld", res,
               [*lines, f"wall time {res['wall_s']:.0f} s"])
    if as_json:
        click.echo(jsonio.dumps(res, indent=1, default=str))
        return
    for line in lines:
        click.echo(line)
    click.echo(f"{res['wall_s']:.0f} s", err=True)
