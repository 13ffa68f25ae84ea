"""``skinkit sysid``: identify skin dynamics from a stochastic force record."""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any

import click

from skinkit import jsonio
from skinkit.cli._paths import check_out_dir
from skinkit.cli._types import FiniteFloat
from skinkit.errors import SkinkitError


def _load(record: Path, protocol: str | None, axis: str) -> Any:
    """A RobotRecord from a CSV file or from an experiment file's protocol."""
    from skinkit.sysid.checks import SysidError

    if record.suffix.lower() == ".csv":
        from skinkit.store import read_robot_csv

        if protocol is not None:
            raise SysidError("--protocol names a record inside an experiment file, not a CSV")
        return read_robot_csv(record, axis=axis)
    from skinkit.store import open_experiment

    with open_experiment(record) as exp:
        names = exp.record_names()
        if protocol is None:
            if len(names) != 1:
                raise SysidError(f"{record} holds {len(names)} records; choose one with "
                                 f"--protocol ({', '.join(names) or 'none'})")
            protocol = names[0]
        elif protocol not in names:
            raise SysidError(f"{record} has no record {protocol!r} (records: "
                             f"{', '.join(names) or 'none'})")
        return exp.read_record(protocol)


def _clean(obj: Any) -> Any:
    """JSON-safe: NaN and infinities become null."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    return obj


#: the figures --plot writes (refused if present without --overwrite)
PLOT_FILES = ("sysid.png", "sysid_residuals.png", "sysid_comparison.png", "incremental.png")


def _check_plot_dir(plot_dir: Path, overwrite: bool) -> None:
    """Refuse ``--plot`` before any work: a folder that cannot be made (under a file, on a
    read-only file system), or earlier figures that would be replaced silently."""
    check_out_dir(plot_dir, "--plot")
    earlier = sorted(f for f in PLOT_FILES if (plot_dir / f).exists())
    if earlier and not overwrite:
        raise SkinkitError(f"--plot {plot_dir}: already holds {', '.join(earlier)} (an earlier result); "
                           "give another folder, or --overwrite to replace them")


@click.command()
@click.argument("record", type=click.Path(path_type=Path, dir_okay=False))
@click.option("--model", type=click.Choice(["linear", "wiener", "hammerstein"]),
              default="linear", show_default=True, help="Model to identify.")
@click.option("--memory", "memory_s", type=FiniteFloat(0.0, 60.0, min_open=True), default=None,
              help="IRF memory in seconds (default: from the IRF's decay).")
@click.option("--protocol", default=None, help="Record name inside an experiment file.")
@click.option("--axis", type=click.Choice(["x", "y", "z"]), default="z", show_default=True,
              help="Tip axis to identify along (z: normal indentation).")
@click.option("--robot-mass", "robot_mass", type=FiniteFloat(0.0, 100.0), default=0.0, show_default=True,
              help="Robot moving mass to remove [kg].")
@click.option("--robot-damping", "robot_damping", type=FiniteFloat(0.0, 1e6), default=0.0,
              show_default=True,
              help="Robot damping to remove [N s/m].")
@click.option("--robot-stiffness", "robot_stiffness", type=FiniteFloat(0.0, 1e9), default=0.0,
              show_default=True,
              help="Robot stiffness to remove [N/m].")
@click.option("--hold", type=click.Choice(["foh", "zoh", "impulse"]), default="foh",
              show_default=True, help="Force between samples: linear (foh, a measured force), "
              "held (zoh, a commanded force) or plain sampling of h(t) (impulse).")
@click.option("--refine", is_flag=True,
              help="Refine K, B, I by output-error least squares after the damped-sinusoid fit.")
@click.option("--two-sided", "two_sided", is_flag=True,
              help="Estimate the IRF at negative lags too (a causality check).")
@click.option("--fit-offset", "fit_offset", is_flag=True,
              help="Wiener: also fit a position offset (when position 0 is not the unloaded "
              "skin surface).")
@click.option("--compare", is_flag=True,
              help="Also identify the other models and compare their residuals.")
@click.option("--incremental", is_flag=True,
              help="Incremental protocol: find the stochastic steps and identify K, B, I in "
              "each (ascending and descending).")
@click.option("--probe-radius", "probe_radius_mm", type=FiniteFloat(0.0, 100.0, min_open=True),
              default=None,
              help="Probe radius [mm]; with --incremental adds E = (1 - nu^2) K / (2 Rp).")
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@click.option("--plot", "plot_dir", type=click.Path(path_type=Path, file_okay=False),
              default=None, help="Write figures (identification, residuals) into this folder.")
@click.option("--overwrite", is_flag=True, help="Replace figures an earlier run left in the --plot folder.")
def sysid(record: Path, model: str, memory_s: float | None, protocol: str | None, axis: str,
          robot_mass: float, robot_damping: float, robot_stiffness: float, hold: str,
          refine: bool, two_sided: bool, fit_offset: bool, compare: bool, incremental: bool,
          probe_radius_mm: float | None, as_json: bool, plot_dir: Path | None, overwrite: bool) -> None:
    """Identify K, B, I (and a Wiener or Hammerstein nonlinearity) from RECORD.

    RECORD is an experiment file (choose the record with --protocol) or a CSV file with
    header time_s,force_N,position_m (uniform sampling; the rate comes from the time column).
    Warnings about the record (gaps, NaNs, clipping, ...) go to stderr and into the JSON.
    A record that is not a broadband stochastic force test (a ramp-and-hold, relaxation or
    displacement-controlled test) is refused with exit status 2; non-physical K, B, I (e.g. a
    negative mass after --robot-mass) are reported as errors, not numbers, also exit 2.
    """
    from skinkit.sysid import RobotDynamics
    from skinkit.sysid.checks import refuse_if_not_stochastic
    from skinkit.sysid.hammerstein import identify_hammerstein_signals
    from skinkit.sysid.linear import identify_signals
    from skinkit.sysid.record import record_signals
    from skinkit.sysid.wiener import identify_wiener_signals

    if plot_dir is not None:
        _check_plot_dir(plot_dir, overwrite)
    rec = _load(record, protocol, axis)
    robot = None
    if robot_mass or robot_damping or robot_stiffness:
        robot = RobotDynamics(mass_kg=robot_mass, damping_Ns_per_m=robot_damping,
                              stiffness_N_per_m=robot_stiffness)
    if incremental:
        _incremental(rec, record, axis, memory_s, robot, hold, probe_radius_mm, as_json, plot_dir)
        return
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            sig = record_signals(rec, axis, memory_s)
            # refuse before identifying: an IRF of a ramp-and-hold record is not worth a number
            refuse_if_not_stochastic(sig.issues, str(record))
            lin = identify_signals(sig, memory_s, robot=robot, hold=hold, two_sided=two_sided,
                                   refine=refine)
            refuse_if_not_stochastic(sig.issues, str(record))  # the causality check runs here
            if model == "linear":
                result: Any = lin
            elif model == "wiener":
                result = identify_wiener_signals(sig, memory_s, linear=lin, fit_offset=fit_offset)
            else:
                result = identify_hammerstein_signals(sig, memory_s, linear=lin)
            models = {}
            if compare:
                models = {"linear": lin,
                          "wiener": result if model == "wiener" else identify_wiener_signals(
                              sig, memory_s, linear=lin, fit_offset=fit_offset),
                          "hammerstein": result if model == "hammerstein" else
                          identify_hammerstein_signals(sig, memory_s, linear=lin)}
        finally:  # the warnings explain an error too
            for w in caught:
                if issubclass(w.category, UserWarning):
                    click.echo(f"warning: {w.category.__name__}: {w.message}", err=True)
    out = _clean(result.to_dict())
    _withhold(out)
    out["record"] = str(record)
    out["protocol"] = rec.protocol.name
    if models:
        from skinkit.sysid.diagnostics import compare as compare_models
        from skinkit.sysid.diagnostics import default_bands

        out["comparison"] = _clean(compare_models(models, sig.force_N, sig.position_m,
                                                  sig.rate_hz, lin.burn_in))
        out["comparison_band_edges_hz"] = default_bands(sig.rate_hz).tolist()
    if plot_dir is not None:
        out["plots"] = _plots(result, sig, lin, plot_dir)
        if models:
            from skinkit.sysid.plots import plot_comparison

            out["plots"].append(str(plot_comparison(out["comparison"],
                                                    default_bands(sig.rate_hz),
                                                    plot_dir / "sysid_comparison.png")))
    if as_json:
        click.echo(jsonio.dumps(out, indent=2))
    else:
        _table(out, model)
    if out["errors"]:
        from skinkit.sysid.checks import NonPhysicalError

        raise NonPhysicalError("; ".join(out["errors"]))


#: per parameter: its value and standard-error keys in the result's dictionary
_SKIN_KEYS = {"K": ("K_N_per_m", "K_se_N_per_m"), "B": ("B_Ns_per_m", "B_se_Ns_per_m"),
              "I": ("I_kg", "I_se_kg")}


def _withhold(out: dict[str, Any]) -> set[str]:
    """Non-physical or meaningless K, B, I are errors, not numbers: null them and what is
    derived from them (the messages in ``out["errors"]`` keep the values). Returns the
    withheld parameters ("K", "B", "I")."""
    from skinkit.sysid.checks import nonphysical

    if not out.get("errors"):
        return set()
    if not out.get("valid", True):
        bad = set(_SKIN_KEYS)
    else:
        vals = [math.nan if out[_SKIN_KEYS[k][0]] is None else out[_SKIN_KEYS[k][0]]
                for k in ("K", "B", "I")]
        bad = set(nonphysical(*vals))
    for k in bad:
        for key in _SKIN_KEYS[k]:
            out[key] = None
    derived = {"gain_m_per_N": {"K"}, "wn_rad_s": {"K", "I"}, "zeta": {"K", "B", "I"}}
    for key, needs in derived.items():
        if needs & bad:
            out[key] = None
    out["withheld"] = sorted(bad)
    return bad


def _duration(seconds: float | None) -> tuple[str, str]:
    """A time as (value, unit), in ms below a second and in s above."""
    from skinkit.cli.render import number

    if seconds is None:
        return "-", "s"
    if abs(seconds) < 1.0:
        return number(seconds * 1e3), "ms"
    return number(seconds), "s"


def _incremental(rec: Any, record: Path, axis: str, memory_s: float | None, robot: Any,
                 hold: str, probe_radius_mm: float | None, as_json: bool,
                 plot_dir: Path | None) -> None:
    from skinkit.cli._progress import progress
    from skinkit.sysid.incremental import identify_incremental

    radius = None if probe_radius_mm is None else probe_radius_mm * 1e-3
    with progress(transient=True) as bar:   # on stderr, also with --json
        res = identify_incremental(rec, axis=axis, memory_s=memory_s, robot=robot, hold=hold,
                                   probe_radius_m=radius,
                                   progress=lambda k, n: bar.update("identifying increments",
                                                                    k / n if n else None, f"{k}/{n}"))
    out: dict[str, Any] = {"record": str(record), "protocol": rec.protocol.name,
                           "increments": res.table(), "hysteresis": res.hysteresis()}
    if plot_dir is not None:
        from skinkit.sysid.plots import plot_incremental

        plot_dir.mkdir(parents=True, exist_ok=True)
        out["plots"] = [str(plot_incremental(out["increments"], plot_dir / "incremental.png"))]
    for row in out["increments"]:
        for w in row["warnings"]:
            click.echo(f"warning: increment {row['index']}: {w}", err=True)
        if row["error"]:
            click.echo(f"warning: increment {row['index']} not identified: {row['error']}",
                       err=True)
    out = _clean(out)
    if as_json:
        click.echo(jsonio.dumps(out, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"sysid incremental: {record} ({rec.protocol.name})")
    for col in ("#", "dir", "force [N]", "position [mm]", "K [N/m]", "B [N s/m]", "I [g]",
                "VAF [%]") + (("E [kPa]",) if radius else ()):
        t.add_column(col, justify="right")
    for r in out["increments"]:
        def g(v: Any, scale: float = 1.0) -> str:
            return "-" if v is None else f"{v * scale:.4g}"

        cells = [str(r["index"]), r["direction"], g(r["mean_force_N"]),
                 g(r["position_mean_m"], 1e3), g(r["K_N_per_m"]), g(r["B_Ns_per_m"]),
                 g(r["I_kg"], 1e3), g(r["vaf_linear_pct"])]
        if radius:
            cells.append(g(r.get("E_Pa"), 1e-3))
        t.add_row(*cells)
    Console().print(t)


def _plots(result: Any, sig: Any, lin: Any, plot_dir: Path) -> list[str]:
    from skinkit.sysid.diagnostics import diagnose, residual_diagnostics
    from skinkit.sysid.plots import plot_identification, plot_residuals

    try:
        plot_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SkinkitError(f"--plot {plot_dir}: cannot create folder ({exc.strerror})") from None
    files = [plot_identification(result, sig.force_N, sig.position_m, plot_dir / "sysid.png")]
    if lin.valid:
        diag = diagnose(result, sig.force_N, sig.position_m, sig.rate_hz, lin.burn_in)
    else:  # diagnose what the non-parametric IRF leaves unexplained
        pred = lin.irf.predict(sig.force_N - sig.force_N.mean()) + sig.position_m.mean()
        diag = residual_diagnostics(sig.force_N, sig.position_m, pred, sig.rate_hz,
                                    burn_in=lin.burn_in, max_lag_s=min(0.1, lin.irf.memory_s))
        result = lin
    files.append(plot_residuals(diag, plot_dir / "sysid_residuals.png",
                                title=f"{type(result).__name__} residuals"))
    return [str(f) for f in files]


def _table(out: dict[str, Any], model: str) -> None:
    from rich.console import Console
    from rich.table import Table

    from skinkit.cli.render import number, text

    def fmt(v: Any, scale: float = 1.0, digits: int = 4) -> str:
        return "-" if v is None else number(v * scale, digits)

    def skin(key: str, scale: float = 1.0) -> str:
        return "[bold red]error[/]" if key[0] in out.get("withheld", ()) else fmt(out[key], scale)

    t = Table(title=f"sysid {model}: {text(out['record'])} ({text(out['protocol'])})")
    t.add_column("quantity")
    t.add_column("value", justify="right")
    t.add_column("unit")
    rows = [("K", skin("K_N_per_m"), "N/m"), ("B", skin("B_Ns_per_m"), "N s/m"),
            ("I", skin("I_kg", 1e3), "g"), ("VAF linear", fmt(out["vaf_linear_pct"]), "%"),
            ("IRF memory", *_duration(out["irf_memory_s"])),
            ("IRF rank", str(out["irf_rank"]), "")]
    if model == "wiener":
        rows += [("Is", fmt(out["Is_s2"]), "s²"), ("Bs", fmt(out["Bs_s"]), "s")]
        if "C1_m" in out:
            rows += [("C1", fmt(out["C1_m"], 1e3), "mm"), ("C2", fmt(out["C2_per_N"]), "1/N")]
        rows += [("VAF Wiener", fmt(out["vaf_wiener_pct"]), "%")]
    if model == "hammerstein":
        rows += [("VAF Hammerstein", fmt(out["vaf_hammerstein_pct"]), "%")]
    for r in rows:
        t.add_row(*r)
    con = Console()
    con.print(t)
    for p in out.get("plots", []):
        con.print(f"plot: {p}")
