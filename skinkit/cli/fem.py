"""``skinkit solve``, ``skinkit verify`` and ``skinkit convergence``: the finite-element engine."""

from __future__ import annotations

import json
from pathlib import Path

import click

from skinkit.cli._paths import check_result_dir, staged_dir
from skinkit.errors import SkinkitError

#: what ``skinkit solve`` writes in its --out folder (and so may replace with --overwrite)
SOLVE_FILES = ("result.h5", "summary.json", "step.pvd", "step_*.vtu")
CONVERGENCE_FILES = ("convergence.json", "convergence.png")


def _model_path(model_file: str) -> Path:
    p = Path(model_file)
    if p.suffix.lower() != ".toml":
        raise SkinkitError(f"MODEL_FILE {model_file}: expected a TOML model file ending in .toml")
    return p


def _fe_spec(path: Path) -> dict:
    """The model file's description, ready for the engine: a lumped model is refused (it has no
    mesh to solve), and ``[[effects]]`` are applied, as the forward models do — solving without
    them would be a silent answer for another model."""
    from skinkit.fem.errors import ModelError
    from skinkit.fem.model import read_model, table
    from skinkit.forward.effects import apply_all, resolve
    from skinkit.forward.spec_check import check_description
    spec = read_model(path)
    check_description(spec)  # the session-driven tables too: a misspelt key is not ignored
    kind = table(spec.get("model", {}), "model").get("kind", "fe")
    if kind == "lumped":
        raise SkinkitError(f"{path}: model.kind = 'lumped' is a lumped model, which has no mesh to "
                           "solve; predict a record with it (skinkit predict MODEL_FILE RECORD)")
    if kind != "fe":
        raise ModelError("model.kind", f"must be 'fe' or 'lumped', got {kind!r}")
    return apply_all(spec, resolve(spec.get("effects"), "fe"))


def _progress(total: float, label: str):
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
    prog = Progress(TextColumn(label), BarColumn(), TextColumn("t = {task.completed:.4g} / {task.total:.4g}"),
                    TimeElapsedColumn(), transient=True)
    return prog


@click.command("solve")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="output directory (default: the model file's name without .toml, in the current "
                   "directory)")
@click.option("--overwrite", is_flag=True, help="replace an earlier result in --out")
@click.option("--json", "as_json", is_flag=True, help="print the JSON summary")
@click.option("--no-vtu", is_flag=True, help="skip the VTU series")
def solve(model_file: str, out_dir: str | None, overwrite: bool, as_json: bool, no_vtu: bool) -> None:
    """Solve MODEL_FILE (TOML); write result.h5, summary.json and a VTU series."""
    from skinkit.fem.model import build_model
    from skinkit.fem.run import solve_model, write_outputs
    # outputs go where the user is, never beside the model file (which may be in the package/docs)
    out = check_result_dir(Path(out_dir) if out_dir else Path.cwd() / _model_path(model_file).stem, "--out",
                           overwrite=overwrite, owned=SOLVE_FILES, command="skinkit solve")
    model = build_model(_fe_spec(_model_path(model_file)))
    times = model.load.times
    # rich formats the label: braces of the model's name are text, not fields
    name = model.name.replace("{", "{{").replace("}", "}}")
    prog = _progress(float(times[-1]), f"solving {name} ({model.mesh.n_dof} dofs)")
    with prog:
        task = prog.add_task("solve", total=float(times[-1]))
        sol, info = solve_model(model, progress=lambda t: prog.update(task, completed=t))
    with staged_dir(out) as tmp:  # nothing appears at --out unless every file is written
        files = write_outputs(model, sol, info, tmp, vtu=not no_vtu)
        info["files"] = {k: str(out / Path(v).relative_to(tmp)) for k, v in files.items()}
    if as_json:
        click.echo(json.dumps(info, indent=2))
        return
    last = info["steps"][-1]
    click.echo(f"{model.name}: {info['dof']} dofs, {len(info['steps'])} steps, "
               f"{info['newton_iterations']} Newton iterations, {info['wall_s']:.2f} s")
    if last["tip_force_N"] is not None:
        click.echo(f"final tip displacement {last['tip_displacement_m']} m, force {last['tip_force_N']} N")
    click.echo(f"wrote {out}")


@click.command("verify")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
@click.option("--case", "cases", multiple=True, help="run only these cases (repeatable)")
def verify(as_json: bool, cases: tuple[str, ...]) -> None:
    """Run the finite-element verification suite (closed forms, patch test, Sneddon, ...)."""
    from skinkit.errors import SkinkitError
    from skinkit.fem import verify as V
    unknown = [c for c in cases if c not in V.names()]
    if unknown:
        raise SkinkitError(f"unknown verification case(s) {unknown}; cases are {V.names()}")
    res = V.run(list(cases) or None,
                progress=None if as_json else (lambda n: click.echo(f"  running {n} ...", err=True)))
    if as_json:
        click.echo(json.dumps(res, indent=2))
    else:
        for c in res["cases"]:
            click.echo(f"{'PASS' if c['passed'] else 'FAIL'} {c['name']}: error {c['error']:.3g} "
                       f"(tolerance {c['tolerance']:.3g}) {c['note']}")
    if not res["passed"]:
        raise SystemExit(1)


@click.command("convergence")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.option("--levels", type=click.IntRange(1, 8), default=3, show_default=True,
              help="refinement levels (1 = as given)")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="directory for convergence.json and convergence.png (default: <model file name>"
                   "_convergence in the current directory)")
@click.option("--overwrite", is_flag=True, help="replace an earlier result in --out")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
def convergence(model_file: str, levels: int, out_dir: str | None, overwrite: bool, as_json: bool) -> None:
    """Mesh refinement study (thesis Figs 6-4, 7-9): final tip force against element count."""
    from skinkit.fem.discretisation import refined_spec as _refined
    from skinkit.fem.model import build_model, check_size, layer_table
    from skinkit.fem.run import solve_model
    path = _model_path(model_file)
    out = check_result_dir(Path(out_dir) if out_dir else Path.cwd() / f"{path.stem}_convergence", "--out",
                           overwrite=overwrite, owned=CONVERGENCE_FILES, command="skinkit convergence")
    spec = _fe_spec(path)
    first = build_model(spec)  # validates every entry before any refinement
    finest = _refined(spec, levels)
    check_size(finest, layer_table(finest))  # refuse now, not after solving the coarse levels
    rows = []
    for lev in range(1, levels + 1):
        model = first if lev == 1 else build_model(_refined(spec, lev))
        _, info = solve_model(model)
        last = info["steps"][-1]
        f = last["tip_force_N"]
        d = last["tip_displacement_m"]
        rows.append({"level": lev, "dof": info["dof"], "elements": info["elements"],
                     "tip_force_N": f, "tip_displacement_m": d, "wall_s": info["wall_s"]})
        if not as_json:
            click.echo(f"level {lev}: {info['dof']} dofs, tip force {f} N, displacement {d} m, "
                       f"{info['wall_s']:.1f} s", err=True)
    key = "tip_force_N" if spec.get("indenter", {}).get("mode", "displacement") == "displacement" \
        else "tip_displacement_m"
    finest = rows[-1][key]
    for r in rows:
        if r[key] is not None and finest is not None:
            r["change_vs_finest"] = abs(r[key][2] - finest[2]) / max(abs(finest[2]), 1e-300)
    res = {"model": spec.get("model", {}).get("name", "model"), "quantity": key, "levels": rows}
    with staged_dir(out) as tmp:
        _write_convergence(res, rows, key, tmp)
    if as_json:
        click.echo(json.dumps(res, indent=2))
    else:
        click.echo(f"wrote {out / 'convergence.json'} and {out / 'convergence.png'}")


def _write_convergence(res: dict, rows: list[dict], key: str, out: Path) -> None:
    (out / "convergence.json").write_text(json.dumps(res, indent=2))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot([r["dof"] for r in rows], [abs(r[key][2]) for r in rows], "o-")
    ax.set_xlabel("degrees of freedom")
    ax.set_ylabel("|tip force| [N]" if key == "tip_force_N" else "|tip displacement| [m]")
    ax.set_xscale("log")
    ax.set_title("mesh convergence")
    fig.tight_layout()
    fig.savefig(out / "convergence.png", dpi=120)
    plt.close(fig)
