"""``skinkit import-extensometer``: a two-pad extensometer record with 2D tracking into an experiment file."""

from __future__ import annotations

from pathlib import Path

import click

from skinkit.cli._order import experiment_first
from skinkit.cli._paths import check_name
from skinkit.cli._types import FiniteFloat
from skinkit.store.dic_import import MARK_SPACING_M, NOMINAL_RATE_HZ, import_extensometer


@click.command("import-extensometer")
@click.argument("experiment", type=click.Path(path_type=Path))
@click.argument("folder", type=click.Path(path_type=Path))
@click.option("--protocol", default="extension", show_default=True, help="Protocol (record and track) name.")
@click.option("--overwrite", is_flag=True, help="Replace EXPERIMENT if it exists.")
@click.option("--rate", "rate_hz", type=FiniteFloat(min=0.0, min_open=True), default=NOMINAL_RATE_HZ,
              show_default=True,
              help="Nominal sampling rate of the device [Hz] (the files have no time stamps).")
@click.option("--mark-spacing", "mark_spacing_mm", type=FiniteFloat(min=0.0, min_open=True),
              default=MARK_SPACING_M * 1e3,
              show_default=True,
              help="Distance between the two marks on one pad [mm]; sets the pixel scale.")
@click.option("--moving-pad", type=click.Choice(["1", "2"]), default="1", show_default=True,
              help="Which pad's marks (x0_ref_N) are on the moving pad.")
@click.option("--frames", type=click.IntRange(min=2), default=None,
              help="Keep only the first N images (the reference image counted), e.g. those the force "
                   "record covers when the camera went on after it ended.  [default: all]")
def import_extensometer_cmd(experiment: Path, folder: Path, protocol: str, overwrite: bool, rate_hz: float,
                            mark_spacing_mm: float, moving_pad: str, frames: int | None) -> None:
    """Import FOLDER (u_moving_pad.dat, f_moving_pad.dat and the tracked points x0/y0/xt/yt
    in pixels; see docs/guide/real-records.md) as a new session EXPERIMENT: one record (pad
    displacement and force along x) and its 2D track in metres in the skin frame.

    The old order FOLDER EXPERIMENT is still read, with a warning, when it is evident (the
    first is a folder, the second an HDF5 file or a new .h5 name)."""
    # before the folder is read: the schema's own refusal would not name the option
    check_name(protocol, "--protocol", "protocol name")
    experiment, folder = experiment_first(experiment, folder, "skinkit import-extensometer")
    imp = import_extensometer(folder, experiment, protocol, overwrite, rate_hz, mark_spacing_mm * 1e-3,
                              int(moving_pad), frames)
    a = imp.track_attrs
    click.echo(f"imported {imp.record.n_samples} force samples (nominal {rate_hz:g} Hz) and "
               f"{imp.track.n_points} points x {imp.track.n_frames} frames as {protocol!r} "
               f"into {experiment}; "
               f"pixel scale {1e-3 / a['pixel_scale_m_per_px']:.4g} px/mm, tracking noise "
               f"{a['noise_m'][0] * 1e6:.3g}/{a['noise_m'][1] * 1e6:.3g} um (x/y), "
               f"{a['invalid_point_frames']} point-frames invalid")
