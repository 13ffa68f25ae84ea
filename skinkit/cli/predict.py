"""``skinkit predict``: a model file driven by a session; how far its predictions are from the data."""

from __future__ import annotations

from pathlib import Path

import click

from skinkit import jsonio
from skinkit.cli._paths import check_out_file
from skinkit.cli._scheduler import scheduler_callback
from skinkit.cli._types import FiniteFloat
from skinkit.errors import SkinkitError
from skinkit.forward.session import read_session
from skinkit.units import unit_suffix


@click.command("predict")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.argument("session", type=click.Path(dir_okay=False))
@click.option("--protocols", default=None,
              help="read only these records of SESSION (comma-separated; default all)")
@click.option("--until", "until_s", type=FiniteFloat(min=0, min_open=True), default=None,
              help="only the first part of every record, up to this time [s]")
@click.option("--holdout", default=None, help="mark these protocols held out (comma-separated)")
@click.option("--segments", type=click.Choice(["cycles"]), default=None,
              help="split every record into protocols first (cycles: one per loading cycle)")
@click.option("--set", "sets", multiple=True, metavar="NAME=VALUE",
              help="override a parameter (SI value or '<number> <unit>'), repeatable")
@click.option("--sensitivities", is_flag=True, help="also compute every parameter's sensitivities")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="worker processes for the protocols (default: one per core)")
@click.option("--scheduler", default=None, metavar="ADDRESS", callback=scheduler_callback,
              help="a Dask scheduler address to solve the protocols on (reached before any work starts)")
@click.option("--axis", type=click.Choice(["x", "y", "z"]), default=None,
              help="tip axis of a one-axis CSV record (default: the model's, else z)")
@click.option("--out", "out_file", type=click.Path(dir_okay=False), default=None,
              help="write the predictions (HDF5) here")
@click.option("--vtu", "vtu_dir", type=click.Path(file_okay=False), default=None,
              help="a finite-element model: write each protocol's fields for ParaView to this directory "
                   "(<protocol>.pvd and one .vtu per step on the 27-node mesh: displacement, Green-Lagrange "
                   "strain, Cauchy stress, fibre directions)")
@click.option("--overwrite", is_flag=True, help="replace an existing --out file or --vtu series")
@click.option("--json", "as_json", is_flag=True, help="print the residual summary as JSON")
def predict(model_file: str, session: str, protocols: str | None, until_s: float | None, holdout: str | None,
            segments: str | None, sets: tuple[str, ...],
            sensitivities: bool, workers: int | None, scheduler: str | None, axis: str | None,
            out_file: str | None, vtu_dir: str | None, overwrite: bool, as_json: bool) -> None:
    """Predict SESSION (experiment file or CSV record) with MODEL_FILE; report the residuals."""
    from skinkit.cli._progress import progress
    from skinkit.fem.model import quantity
    from skinkit.forward import load
    from skinkit.forward.residuals import summarise

    if out_file:   # before any prediction: an earlier file is not replaced silently
        out = check_out_file(out_file, "--out")
        if out.exists() and not overwrite:
            raise SkinkitError(f"--out {out}: already exists (an earlier result); give another --out, "
                               "or --overwrite to replace it")

    model = load(model_file, workers=workers, scheduler=scheduler)
    try:
        if vtu_dir and getattr(model, "kind", None) != "fe":   # before the session is read
            raise SkinkitError(f"--vtu: model {model.name!r} is lumped; only a finite-element model has "
                               "fields to write")
        obs = read_session(model, session, holdout, segments, axis, protocols)
        if until_s is not None:
            obs = obs.until(until_s)
        params = model.parameters()
        values = {}
        for item in sets:
            name, eq, val = item.partition("=")
            if not eq:
                raise SkinkitError(f"--set {item!r}: expected NAME=VALUE")
            name = name.strip()
            if name not in params:
                raise SkinkitError(f"--set {name!r}: no such parameter; the model has {params.names}")
            values[name] = quantity(val.strip() if not _is_number(val) else float(val),
                                    params.param(name).unit,
                                    f"--set {name}")
        params = params.with_values(values) if values else params
        extra = {"fields_dir": _check_vtu(model, obs, vtu_dir, overwrite)} if vtu_dir else {}
        with progress() as bar, bar.feeding("predict"):   # on stderr, also with --json
            pred = model.predict(params, obs, sensitivities=sensitivities, **extra)
        summary = summarise(pred, obs)
        if not summary["samples"]:
            # a residual over no sample (chi2 nan) would read as a prediction that ran
            raise SkinkitError(_nothing_predicted(model, session, axis))
        summary.update(_calibrated_dof(model_file, summary))
        summary["model"] = model.name
        summary["session"] = str(session)
        summary["inputs"] = pred.inputs
        summary["methods"] = pred.methods
        summary["solver"] = {k: v for k, v in pred.info.items() if k != "protocols"}
        if out_file:
            _write(Path(out_file), pred, summary)
            summary["file"] = out_file
        if vtu_dir:
            summary["vtu"] = {p: i["vtu"] for p, i in pred.info["protocols"].items()}
    finally:
        model.close()
    if as_json:
        click.echo(jsonio.dumps(summary, indent=2, default=float))
        return
    _echo(summary, model.name, session)


def _echo(summary: dict, name: str, session: str) -> None:
    """The residual summary as text: the whole, the calibrated figure, per protocol and channel."""
    click.echo(f"{name} on {session}: chi2/sample {summary['chi2_per_sample']:.3g} over "
               f"{summary['samples']} samples (noise alone: {summary['noise_only_range_999'][0]:.3g}.."
               f"{summary['noise_only_range_999'][1]:.3g})")
    if "chi2_per_dof" in summary:
        cal = summary["calibration"]
        fit = cal["fit_chi2_per_dof"]
        click.echo(f"  calibrated model: chi2/dof {summary['chi2_per_dof']:.6g} over {cal['dof']} dof "
                   f"({cal['fitted_parameters']} fitted parameters)"
                   + (f"; the fit reported {fit:.6g}" if isinstance(fit, float) else ""))
    for proto, chans in summary["protocols"].items():
        for cname, c in chans.items():
            rms = ", ".join(f"{v:.3g}" for v in c["rms"])
            click.echo(f"  {proto:24s} {cname:13s} chi2/n {c['chi2_per_sample']:9.3g}  "
                       f"rms [{rms}]{unit_suffix(c['unit'])}"
                       f"{'  (held out)' if c['held_out'] else ''}")
    for path in summary.get("vtu", {}).values():
        click.echo(f"wrote {path}")


def _calibrated_dof(model_file: str, summary: dict) -> dict:
    """For a calibrated model file (its ``[calibration]`` table lists the fitted parameters):
    ``chi2_per_dof`` = χ² / (samples − fitted parameters), the figure the fit reported, and the
    fit's own under ``calibration``; nothing for another model file."""
    from skinkit.errors import SkinkitError as _Unreadable
    from skinkit.fem.model import read_model
    from skinkit.inverse.calibrated import CALIBRATION_TABLE

    try:
        cal = read_model(model_file).get(CALIBRATION_TABLE)
    except (OSError, ValueError, _Unreadable):   # read again here only for its [calibration] table
        return {}
    if not isinstance(cal, dict) or not isinstance(cal.get("parameters"), dict):
        return {}
    k = len(cal["parameters"])
    dof = max(int(summary["samples"]) - k, 1)
    return {"chi2_per_dof": float(summary["chi2"]) / dof,
            "calibration": {"fitted_parameters": k, "dof": dof,
                            "fit_chi2_per_dof": cal.get("chi2_per_dof"), "session": cal.get("session")}}


def _check_vtu(model, obs, vtu_dir: str, overwrite: bool) -> Path:
    """--vtu: a folder holding none of the protocols' series (unless --overwrite)."""
    from skinkit.cli._paths import check_result_files

    return check_result_files(vtu_dir, [f"{p}.pvd" for p in obs.names], "--vtu", overwrite=overwrite)


def _nothing_predicted(model, session: str, axis: str | None) -> str:
    """Why a prediction covers no recorded sample, as one line naming --axis when it was given."""
    own = getattr(model, "axis", None)
    predicts = f"; model {model.name!r} predicts the {own} axis" if own in ("x", "y", "z") else ""
    if axis is not None:
        return f"--axis {axis}: no sample of {session} is predicted on that axis{predicts}"
    return f"{session}: no recorded sample is predicted by model {model.name!r}{predicts}"


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def _write(path: Path, pred, summary: dict) -> None:
    """Predictions and sensitivities as HDF5 (written to a temporary name, then renamed)."""
    import os

    import h5py

    tmp = path.with_name(path.name + ".part")
    try:
        with h5py.File(tmp, "w") as f:
            f.attrs["summary"] = jsonio.dumps(summary, default=float)
            for proto, cname, cp in pred.items():
                g = f.require_group(f"{proto}/{cname}")
                g.create_dataset("values", data=cp.values)
                for k, d in cp.d.items():
                    g.create_dataset(f"d/{k}", data=d)
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise SkinkitError(f"--out {path}: cannot write ({exc.strerror or exc})") from None
