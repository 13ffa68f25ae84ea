"""``skinkit import-images | import-calibration | import-tracks``: a lab's own camera data in."""

from __future__ import annotations

from pathlib import Path

import click

from skinkit.cli._types import FiniteFloat


@click.command("import-images")
@click.argument("experiment", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--camera", "cameras", nargs=2, multiple=True, required=True, metavar="NAME GLOB",
              help="a camera's name and its image files: a quoted glob ('cam0/*.tif') or a folder; "
                   "repeat once per camera, in the rig's order")
@click.option("--name", default="images", show_default=True,
              help="name of the image sequence in EXPERIMENT (e.g. calibration, indentation)")
@click.option("--match", type=click.Choice(["auto", "name", "order"]), default="auto", show_default=True,
              help="match frames across cameras by the number in the file names, or by sort order "
                   "(auto: by name when every camera's names carry distinct numbers)")
@click.option("--fps", default=1.0, show_default=True, type=FiniteFloat(min=0.0, min_open=True),
              help="frame rate [Hz]: frame k is stored at k / fps seconds")
def import_images(experiment: Path, cameras: tuple[tuple[str, str], ...], name: str, match: str,
                  fps: float) -> None:
    """Import image files (TIFF, PNG, BMP, JPEG; 8/16-bit) of each camera into EXPERIMENT
    (created if it does not exist), for `skinkit vision calibrate | profile | track-3d`."""
    from skinkit.cli._paths import check_name
    from skinkit.cli._progress import progress
    from skinkit.vision.image_import import import_images as run
    from skinkit.vision.image_import import plan_frames

    # before the progress bar: the error is then its only line
    check_name(name, "--name", "image sequence name")
    for cam, _ in cameras:
        check_name(cam, "--camera", "camera name")
    plan = plan_frames(cameras, match)
    with progress(transient=True) as bar:
        done = run(experiment, plan, name, fps,
                   lambda k, n: bar.update(f"importing {name}", k / n if n else None, f"{k}/{n} frames"))
    w, h = done.image_size
    click.echo(f"imported {done.n_frames} frames x {len(done.camera_names)} cameras "
               f"({', '.join(done.camera_names)}), {w}x{h} px {done.dtype}, matched by {done.matched_by}, "
               f"as image sequence {done.name!r} into {experiment}")


@click.command("import-calibration")
@click.argument("experiment", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False, path_type=Path))
@click.option("--unit", type=click.Choice(["m", "mm", "cm", "um"]), default=None,
              help="length unit of the files' translations T (the unit the board was measured in)")
@click.option("--replace", is_flag=True, help="replace a rig the file already holds")
def import_calibration(experiment: Path, files: tuple[Path, ...], unit: str | None, replace: bool) -> None:
    """Import a camera calibration written by OpenCV (cv::FileStorage YAML or XML: one file per
    camera, or one file with several) as the rig of EXPERIMENT's cameras."""
    from skinkit.vision.calibration_io import import_calibration as run

    rig = run(experiment, files, unit, replace)
    for cam in rig.cameras:
        w, h = cam.image_size
        click.echo(f"{cam.name}: f = {cam.K[0, 0]:.1f} px, {w}x{h} px, centre "
                   f"({', '.join(f'{v * 1e3:.1f}' for v in cam.centre)}) mm")
    click.echo(f"rig of {len(rig.cameras)} cameras stored in {experiment}")


@click.command("import-tracks")
@click.argument("experiment", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("csv_file", type=click.Path(path_type=Path))
@click.option("--name", default=None,
              help="track name in EXPERIMENT (default: the file's stem, or the folder's name)")
@click.option("--format", "fmt", type=click.Choice(["csv", "dice", "vic3d", "multidic"]), default=None,
              help="format of CSV_FILE (default: told by its header, or .mat): csv (frame, point, "
                   "x_mm, ...), dice (DICe_solution_*.txt per frame), vic3d (Vic-3D CSV export per "
                   "frame) or multidic (MultiDIC's DIC3DPPresults .mat)")
@click.option("--columns", type=click.Choice(["metric", "pixel"]), default=None,
              help="which coordinates to read from a file holding both pixel columns (x, y, "
                   "COORDINATE_X, *_px) and metric ones (X, Y, Z, MODEL_COORDINATES_X, *_mm)")
@click.option("--unit", type=click.Choice(["m", "mm", "cm", "um", "px"]), default=None,
              help="unit of coordinate columns named without one (x, y, z; X, Y, Z; DICe's MODEL_*; "
                   "MultiDIC's Points3D)")
@click.option("--m-per-px", type=FiniteFloat(min=0.0, min_open=True), default=None,
              help="scale of pixel coordinates [m/px]")
@click.option("--fps", default=1.0, show_default=True, type=FiniteFloat(min=0.0, min_open=True),
              help="frame rate [Hz] when the CSV has no time column: frame k at k / fps seconds")
@click.option("--ignore", multiple=True, help="a column to skip (e.g. a correlation score); repeatable")
@click.option("--overwrite", is_flag=True, help="replace a track of that name")
def import_tracks(experiment: Path, csv_file: Path, name: str | None, fmt: str | None, columns: str | None,
                  unit: str | None, m_per_px: float | None, fps: float, ignore: tuple[str, ...],
                  overwrite: bool) -> None:
    """Import 2D/3D point tracks from another DIC tool as a track in EXPERIMENT (created if it
    does not exist). CSV_FILE: a tracks CSV (frame, point, x_mm, y_mm[, z_mm], or one row per
    frame), per-frame DICe / Vic-3D exports (one file, a folder or a quoted glob), or MultiDIC's
    3D results (.mat)."""
    from skinkit.cli._paths import check_name
    from skinkit.store.dic_formats import default_track_name
    from skinkit.store.track_import import import_tracks as run

    if name is not None:   # an empty --name is refused, not read as "the CSV file's stem"
        check_name(name, "--name", "track name")
    imp = run(experiment, csv_file, name, unit, m_per_px, fps, ignore, overwrite, fmt=fmt, columns=columns)
    t = imp.track
    a = imp.attrs
    how = f"{a['format']}" + (f", {a['columns']} columns" if "columns" in a else "")
    click.echo(f"imported {t.n_points} points x {t.n_frames} frames ({a['dimensions']}D, {how}, "
               f"{int(t.valid.sum())} valid positions) as track {name or default_track_name(csv_file)!r} "
               f"into {experiment}")
