"""``skinkit solve``, ``skinkit verify`` and ``skinkit convergence``: the finite-element engine."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from skinkit import jsonio
from skinkit.cli._paths import check_result_dir, staged_dir
from skinkit.cli._progress import progress
from skinkit.cli._types import FiniteFloat
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


@click.command("solve")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="output directory (default: the model file's name without .toml, in the current "
                   "directory)")
@click.option("--overwrite", is_flag=True, help="replace an earlier result in --out")
@click.option("--json", "as_json", is_flag=True, help="print the JSON summary")
@click.option("--no-vtu", is_flag=True, help="skip the VTU series")
@click.option("--error-estimate", is_flag=True,
              help="also solve on a mesh refined 2x (3x too with --error-levels 3) and report the "
                   "estimated discretisation error of tip force, tip motion and tracked points "
                   "(Richardson extrapolation)")
@click.option("--error-levels", type=click.IntRange(2, 3), default=2, show_default=True,
              help="meshes for --error-estimate: 2 (1x, 2x; order 1 assumed) or 3 (1x, 2x, 3x; "
                   "order measured, about 27x the unknowns)")
def solve(model_file: str, out_dir: str | None, overwrite: bool, as_json: bool, no_vtu: bool,
          error_estimate: bool, error_levels: int) -> None:
    """Solve MODEL_FILE (TOML); write result.h5, summary.json and a VTU series.

    With --error-estimate, or when the file's [solver] sets discretisation_tolerance or
    point_tolerance (then the mesh is refined until the estimate meets it), the estimated
    discretisation error is reported beside the result."""
    from skinkit.fem.model import build_model
    from skinkit.fem.run import solve_model, solve_with_estimate, write_outputs
    # outputs go where the user is, never beside the model file (which may be in the package/docs)
    out = check_result_dir(Path(out_dir) if out_dir else Path.cwd() / _model_path(model_file).stem, "--out",
                           overwrite=overwrite, owned=SOLVE_FILES, command="skinkit solve")
    spec = _fe_spec(_model_path(model_file))
    model = build_model(spec)
    end = float(model.load.times[-1])
    controlled = model.discretisation_tolerance is not None or model.point_tolerance is not None
    label = f"solving {model.name} ({model.mesh.n_dof} dofs)"
    with progress(transient=True) as bar:   # on stderr, also with --json

        def tick(t: float) -> None:   # the solver's load time t, of the programme's end
            bar.update(label, t / end if end > 0 else None, f"t = {t:.4g} / {end:.4g}")

        if error_estimate or controlled:
            model, sol, info = solve_with_estimate(spec, error_levels, progress=tick,
                                                       log=lambda m: bar.say(m, stdout=True))
        else:
            sol, info = solve_model(model, progress=tick)
    with staged_dir(out) as tmp:  # nothing appears at --out unless every file is written
        files = write_outputs(model, sol, info, tmp, vtu=not no_vtu)
        info["files"] = {k: str(out / Path(v).relative_to(tmp)) for k, v in files.items()}
    if as_json:
        click.echo(jsonio.dumps(info, indent=2))
        return
    last = info["steps"][-1]
    click.echo(f"{model.name}: {info['dof']} dofs, {len(info['steps'])} steps, "
               f"{info['newton_iterations']} Newton iterations, {info['wall_s']:.2f} s")
    if last["tip_force_N"] is not None:
        click.echo(f"final tip displacement {last['tip_displacement_m']} m, force {last['tip_force_N']} N")
    if "discretisation" in info:
        click.echo(_error_line(info["discretisation"]))
    click.echo(f"wrote {out}")


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100 * x:.2g} %"


def _error_line(d: dict) -> str:
    """One line: the estimated discretisation error of a solve (its ``discretisation`` block)."""
    order = "n/a" if d["order"] is None else f"{d['order']:.2g}"
    how = "assumed" if d["order_assumed"] else "observed"
    parts = [f"tip force {_pct(d['tip_force_relative_error'])}",
             f"tip motion {_pct(d['tip_displacement_relative_error'])}"]
    if d["points_max_error_m"] is not None:
        parts.append(f"points {1e6 * d['points_max_error_m']:.3g} µm")
    meshes = ", ".join(f"{f}x" for f in d["factors"])
    dof = d["dof"][d["factors"].index(d["factor"])]
    line = (f"estimated discretisation error on the {d['factor']}x mesh ({dof:,} unknowns): "
            f"{', '.join(parts)} (Richardson over {meshes}, order {order} {how})")
    if "met" in d:
        tol = [f"{_pct(d['tolerance'])} on the tip" if d["tolerance"] is not None else "",
               f"{1e6 * d['point_tolerance']:.3g} µm on points" if d["point_tolerance"] is not None else ""]
        line += (f"; tolerance {' and '.join(t for t in tol if t)} met, "
                 f"{d['unknowns_solved']:,} unknowns solved in all")
    return line


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
    with progress() as bar:
        res = V.run(list(cases) or None, progress=lambda n: bar.say(f"  running {n} ..."))
    if as_json:
        click.echo(jsonio.dumps(res, indent=2))
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
@click.option("--order", type=FiniteFloat(min=0, min_open=True), default=None,
              help="convergence order to assume (default: measured from the three finest levels; "
                   "1 with two levels)")
@click.option("--factors", default=None, metavar="F1,F2,...",
              help="refinement factors to solve instead of 1..LEVELS, increasing, whole numbers or "
                   "fractions (e.g. 1/2,1: the file's mesh and one coarsened 2x, each count halved, "
                   "for a mesh whose 2x refinement is too large to solve)")
@click.option("--at", "at", type=click.Choice(["final", "peak"]), default="final", show_default=True,
              help="the load step compared: the programme's last, or its peak (the step where the "
                   "prescribed tip quantity is largest: a sinusoid's deepest point)")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
def convergence(model_file: str, levels: int, out_dir: str | None, overwrite: bool, order: float | None,
                factors: str | None, at: str, as_json: bool) -> None:
    """Mesh refinement study (thesis Figs 6-4, 7-9): final (or peak) tip force against element count.

    With two levels or more, each level's estimated discretisation error (Richardson
    extrapolation: the extrapolated value and the observed order) is reported."""
    from skinkit.fem.discretisation import parse_factor
    from skinkit.fem.discretisation import refined_spec as _refined
    from skinkit.fem.model import build_model, check_size, layer_table
    from skinkit.fem.run import solve_model
    path = _model_path(model_file)
    facs = [parse_factor(1 + i) for i in range(levels)] if factors is None else \
        [parse_factor(x) for x in factors.split(",")]
    if any(not b > a for a, b in zip(facs, facs[1:], strict=False)):
        raise SkinkitError(f"--factors {factors}: refinement factors must increase")
    out = check_result_dir(Path(out_dir) if out_dir else Path.cwd() / f"{path.stem}_convergence", "--out",
                           overwrite=overwrite, owned=CONVERGENCE_FILES, command="skinkit convergence")
    spec = _fe_spec(path)
    first = build_model(spec)  # validates every entry before any refinement
    specs = [_refined(spec, f) for f in facs]  # a count a fraction does not divide is refused now
    check_size(specs[-1], layer_table(specs[-1]))  # refuse now, not after solving the coarse levels
    rows = []
    with progress() as bar:
        for lev, (fac, sp) in enumerate(zip(facs, specs, strict=True), start=1):
            model = first if fac == 1 else build_model(sp)
            end, label = float(model.load.times[-1]), f"level {lev} ({fac}x, {model.mesh.n_dof} dofs)"
            _, info = solve_model(
                model, progress=lambda t, e=end, k=label: bar.update(k, t / e if e else None))
            step = len(info["steps"]) - 1 if at == "final" else _peak_step(info, spec)
            last = info["steps"][step]
            f = last["tip_force_N"]
            d = last["tip_displacement_m"]
            rows.append({"level": lev, "factor": str(fac), "dof": info["dof"], "elements": info["elements"],
                         "step": step, "tip_force_N": f, "tip_displacement_m": d, "wall_s": info["wall_s"]})
            bar.say(f"level {lev} ({fac}x): {info['dof']} dofs, tip force {f} N, displacement {d} m, "
                    f"{info['wall_s']:.1f} s")
    key = "tip_force_N" if spec.get("indenter", {}).get("mode", "displacement") == "displacement" \
        else "tip_displacement_m"
    finest = rows[-1][key]
    for r in rows:
        if r[key] is not None and finest is not None:
            # the size of the vector: a pull along x (twopad) is not its z component
            r["change_vs_finest"] = float(np.linalg.norm(np.subtract(r[key], finest))
                                          / max(float(np.linalg.norm(finest)), 1e-300))
    res = {"model": spec.get("model", {}).get("name", "model"), "quantity": key, "levels": rows}
    res.update(_estimate_levels(rows, key, order))
    with staged_dir(out) as tmp:
        _write_convergence(res, rows, key, tmp)
    if as_json:
        click.echo(jsonio.dumps(res, indent=2))
        return
    for r in rows:
        if r.get("relative_error") is not None:
            click.echo(f"level {r['level']} ({r['factor']}x): {r['dof']:,} unknowns, "
                       f"estimated error {_pct(r['relative_error'])}")
    if res["extrapolated"] is not None:
        how = "assumed" if res["order_assumed"] else "observed"
        o = "n/a" if res["order"] is None else f"{res['order']:.3g}"
        click.echo(f"extrapolated {key} {res['extrapolated']} (order {o} {how})")
    click.echo(f"wrote {out / 'convergence.json'} and {out / 'convergence.png'}")


def _peak_step(info: dict, spec: dict) -> int:
    """Index of the step where the prescribed tip quantity (the motion under displacement
    control, the force under force control) is largest: the same on every mesh."""
    key = "tip_force_N" if spec.get("indenter", {}).get("mode", "displacement") == "force" \
        else "tip_displacement_m"
    mags = [float(np.linalg.norm(st[key])) if st.get(key) is not None else -1.0 for st in info["steps"]]
    return int(np.argmax(mags))


def _estimate_levels(rows: list[dict], key: str, order: float | None) -> dict:
    """Richardson over the levels' final ``key`` vectors: adds to each row ``estimated_error``
    (3,) and ``relative_error`` (its length over the extrapolated value's), and returns
    ``extrapolated``, ``observed_order``, ``order``, ``order_assumed`` (None with one level)."""
    from fractions import Fraction

    from skinkit.fem.discretisation import ASSUMED_ORDER, richardson
    none = {"extrapolated": None, "observed_order": None, "order": None, "order_assumed": None}
    vals = [r[key] for r in rows]
    if len(rows) < 2 or any(v is None or None in v for v in vals):
        return none
    assumed = order is None and len(rows) < 3
    est = richardson([np.array(v, float) for v in vals], [float(Fraction(r["factor"])) for r in rows],
                     ASSUMED_ORDER if assumed else order)
    ext = np.asarray(est["extrapolated"])
    scale = float(np.linalg.norm(ext))
    for r, e in zip(rows, est["errors"], strict=True):
        r["estimated_error"] = e.tolist()
        r["relative_error"] = float(np.linalg.norm(e)) / scale if scale > 0 else 0.0

    def num(x: float) -> float | None:
        return None if not np.isfinite(x) else float(x)
    return {"extrapolated": ext.tolist(), "observed_order": num(est["observed_order"]),
            "order": num(est["order"]), "order_assumed": assumed}


def _write_convergence(res: dict, rows: list[dict], key: str, out: Path) -> None:
    (out / "convergence.json").write_text(jsonio.dumps(res, indent=2))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5, 3.5))
    dof = [r["dof"] for r in rows]
    ax.plot(dof, [float(np.linalg.norm(r[key])) for r in rows], "o-", label="solved")
    if res.get("extrapolated") is not None:
        errs = [float(np.linalg.norm(r["estimated_error"])) for r in rows]
        ax.errorbar(dof, [float(np.linalg.norm(r[key])) for r in rows], yerr=errs, fmt="none",
                    capsize=3, color="C0", label="± estimated error")
        o = res["order"]
        ax.axhline(float(np.linalg.norm(res["extrapolated"])), ls="--", color="C1",
                   label=f"extrapolated (order {'n/a' if o is None else f'{o:.2g}'}"
                         f"{', assumed' if res['order_assumed'] else ''})")
        ax.legend(fontsize=7)
    ax.set_xlabel("degrees of freedom")
    ax.set_ylabel("|tip force| [N]" if key == "tip_force_N" else "|tip displacement| [m]")
    ax.set_xscale("log")
    from matplotlib.ticker import NullFormatter
    ax.xaxis.set_minor_formatter(NullFormatter())  # minor labels of a short decade overlap
    ax.set_title("mesh convergence")
    fig.tight_layout()
    fig.savefig(out / "convergence.png", dpi=120)
    plt.close(fig)
