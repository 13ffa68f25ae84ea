"""``skinkit vision``: calibrate a rig, profile the surface, track points in 2D and 3D."""

from __future__ import annotations

import math
import os
from collections.abc import Collection, Mapping
from typing import Any

import click
from click.core import ParameterSource

from skinkit import jsonio
from skinkit.cli._paths import name_callback
from skinkit.cli._types import FiniteFloat
from skinkit.cli.registry import LazyGroup
from skinkit.errors import SkinkitError

#: the device calibration (``/calibrations/<name>``) where ``calibrate`` notes its board views
RIG_CALIBRATION = "rig"


@click.group("vision", cls=LazyGroup)
def vision() -> None:
    """Stereo vision: calibration, surface profiling, 2D and 3D tracking."""


def _num(x: float) -> float | None:
    return None if not math.isfinite(float(x)) else float(x)


@vision.command("track")
@click.argument("ref_image", type=click.Path(dir_okay=False))
@click.argument("cur_image", type=click.Path(dir_okay=False))
@click.option("--points", "points_csv", required=True, type=click.Path(dir_okay=False),
              help="CSV with header x_px,y_px: points in REF_IMAGE (origin: centre of the top-left pixel)")
@click.option("--subset", "subset_px", default=64, show_default=True, type=click.IntRange(8, 4096),
              help="subset side [px]")
@click.option("--tracker", "tracker_name", default="gn", show_default=True,
              help="tracker plugin (skinkit.trackers)")
@click.option("--search", "search_px", default=None, type=click.IntRange(0, 4096),
              help="integer search radius [px]")
@click.option("--json", "as_json", is_flag=True, help="print JSON instead of a table")
def track(ref_image: str, cur_image: str, points_csv: str, subset_px: int, tracker_name: str,
          search_px: int | None, as_json: bool) -> None:
    """Track POINTS from REF_IMAGE to CUR_IMAGE; print each point's displacement [px]."""
    from skinkit import registry
    from skinkit.vision.imageio import read_gray, read_points_csv

    ref = read_gray(ref_image)
    cur = read_gray(cur_image)
    if ref.shape != cur.shape:
        raise SkinkitError(f"image sizes differ: {ref_image} is {ref.shape[1]}x{ref.shape[0]}, "
                           f"{cur_image} is {cur.shape[1]}x{cur.shape[0]} (width x height)")
    pts = read_points_csv(points_csv)
    kwargs = {} if search_px is None else {"search_px": search_px}
    tracker = registry.create("skinkit.trackers", tracker_name, **kwargs)
    res = tracker.track(ref, cur, pts, subset_px)
    rows = [{"x_px": float(p[0]), "y_px": float(p[1]), "dx_px": _num(d[0]), "dy_px": _num(d[1]),
             "quality": _num(q), "valid": bool(v), "reason": r}
            for p, d, q, v, r in zip(pts, res.displacement_px, res.quality, res.valid, res.reason,
                                     strict=True)]
    if as_json:
        click.echo(jsonio.dumps({"points": rows}, indent=1))
        return
    for row in rows:
        if row["valid"]:
            click.echo(f"({row['x_px']:.2f}, {row['y_px']:.2f}): dx {row['dx_px']:+.4f} px, "
                       f"dy {row['dy_px']:+.4f} px, quality {row['quality']:.3f}")
        else:
            click.echo(f"({row['x_px']:.2f}, {row['y_px']:.2f}): invalid: {row['reason']}")
    n_ok = sum(r["valid"] for r in rows)
    click.echo(f"{n_ok} of {len(rows)} points tracked with {tracker_name}")


def _parse_board(text: str) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise SkinkitError(f"--board {text!r}: expected COLSxROWS (inner corners, squares or dots), "
                           "e.g. 9x6") from None
    return cols, rows


def _images(exp: object, name: str | None, of_skin: bool = False) -> object:
    """The image sequence ``name`` (the only one when None); ``of_skin``: refuse the board
    views the rig was calibrated from (profiling and tracking need the speckled skin)."""
    names = exp.image_names()  # type: ignore[attr-defined]
    if not names:
        raise SkinkitError(f"{exp.path}: holds no image sequences")  # type: ignore[attr-defined]
    board = None
    if of_skin and RIG_CALIBRATION in exp.calibration_names():  # type: ignore[attr-defined]
        board = exp.read_calibration(RIG_CALIBRATION).get("images")  # type: ignore[attr-defined]
    if name is None:
        skin = [n for n in names if n != board]
        if len(skin) > 1:
            raise SkinkitError(f"several image sequences ({', '.join(names)}): choose one with --images")
        name = skin[0] if skin else names[0]
    if name not in names:
        raise SkinkitError(f"--images {name!r}: no such image sequence; the file holds {', '.join(names)}")
    if name == board:
        others = [n for n in names if n != board]
        where = f" ({', '.join(others)})" if others else " (import them with skinkit import-images)"
        raise SkinkitError(f"--images {name!r}: holds the board views the rig was calibrated from, not "
                           f"the speckled skin; choose the skin's images{where}")
    return exp.read_images(name)  # type: ignore[attr-defined]


@vision.command("calibrate")
@click.argument("experiment", type=click.Path(dir_okay=False))
@click.option("--images", "images_name", default=None, help="image sequence of board views")
@click.option("--target", type=click.Choice(["checkerboard", "charuco", "dotgrid"]), default=None,
              help="calibration target  [default: checkerboard]")
@click.option("--board", "--grid", "board_text", default="9x6", show_default=True,
              help="checkerboard: inner corners COLSxROWS; ChArUco: squares COLSxROWS; "
                   "dot grid: dots COLSxROWS")
@click.option("--square-mm", "--pitch-mm", "square_mm", default=3.0, show_default=True,
              type=FiniteFloat(0.0, 1000.0, min_open=True),
              help="board square side, or the dot grid's pitch [mm]")
@click.option("--charuco", is_flag=True, help="the board is a ChArUco board (same as --target charuco)")
@click.option("--marker-mm", default=None, type=FiniteFloat(0.0, 1000.0, min_open=True),
              help="ChArUco marker side [mm] (default 0.75 square)")
@click.option("--dictionary", default="DICT_4X4_50", show_default=True, help="ChArUco ArUco dictionary")
@click.option("--fiducials", "fiducials_text", default="hollow", show_default=True,
              help="dot grid: none, hollow or large fiducial dots, at the default L (1,1 2,1 1,2) or "
                   "at KIND:I,J;I,J;... (grid column, row from 0)")
@click.option("--asymmetric", is_flag=True, help="dot grid: OpenCV's asymmetric circle grid (staggered rows)")
@click.option("--min-views", default=4, show_default=True, type=click.IntRange(1, 100_000),
              help="board views each camera needs")
@click.option("--overwrite", is_flag=True, help="replace a rig already stored in EXPERIMENT")
def calibrate_cmd(experiment: str, images_name: str | None, target: str | None, board_text: str,
                  square_mm: float, charuco: bool, marker_mm: float | None, dictionary: str,
                  fiducials_text: str, asymmetric: bool, min_views: int, overwrite: bool) -> None:
    """Calibrate the rig from board views in EXPERIMENT and store it there."""
    import cv2

    from skinkit.store import open_experiment
    from skinkit.vision.calibration import calibrate, calibrate_charuco
    from skinkit.vision.scene import CharucoTarget

    if charuco and target not in (None, "charuco"):
        raise SkinkitError(f"--charuco contradicts --target {target}")
    target = "charuco" if charuco else (target or "checkerboard")
    size = _parse_board(board_text)
    grid = _dot_grid(size, square_mm, fiducials_text, asymmetric) if target == "dotgrid" else None
    if target == "charuco" and not hasattr(cv2.aruco, dictionary):
        raise SkinkitError(f"--dictionary {dictionary!r} is not an OpenCV ArUco dictionary")
    # refused before calibrating, and before the file is opened to write (which would touch it)
    with open_experiment(experiment) as exp:
        if exp.camera_names() and not overwrite:
            raise SkinkitError(f"{experiment} already holds a rig ({', '.join(exp.camera_names())}); "
                               "--overwrite to replace it")
        _images(exp, images_name)
    with open_experiment(experiment, mode="a") as exp:
        seq = _images(exp, images_name)
        names = seq.camera_names  # type: ignore[attr-defined]
        if target == "charuco":
            marker = (marker_mm if marker_mm is not None else 0.75 * square_mm) * 1e-3
            board = CharucoTarget(size, square_mm * 1e-3, marker, dictionary)
            cal = calibrate_charuco(seq.frames, board, camera_names=names,  # type: ignore[attr-defined]
                                    min_views=min_views)
        elif grid is not None:
            from skinkit.vision.dotgrid_detect import calibrate_dotgrid

            cal = calibrate_dotgrid(seq.frames, grid, camera_names=names,  # type: ignore[attr-defined]
                                    min_views=min_views)
        else:
            cal = calibrate(seq.frames, size, square_mm * 1e-3, camera_names=names,  # type: ignore[attr-defined]
                            min_views=min_views)
        exp.write_rig(cal.rig)
        views = cal.detections.found.sum(axis=0)
        # where the rig came from: profile and track-3d refuse these board views as skin images
        record = {"images": seq.name, "board": board_text, "square_mm": square_mm,  # type: ignore[attr-defined]
                  "charuco": target == "charuco", "target": target}
        if grid is not None:
            record.update({"fiducials": fiducials_text, "asymmetric": asymmetric})
        exp.write_calibration(RIG_CALIBRATION, {
            **record, "rms_px": float(cal.rms_px),
            "per_camera_rms_px": [float(x) for x in cal.per_camera_rms_px], "views": [int(v) for v in views]})
    what = "dot grid" if grid is not None else "board"
    for name, rms, n in zip(cal.rig.names, cal.per_camera_rms_px, views, strict=True):
        click.echo(f"{name}: {n} {what} views, reprojection RMS {rms:.3f} px")
    click.echo(f"overall reprojection RMS {cal.rms_px:.3f} px; rig stored in {experiment} "
               f"(world frame: the {what} in frame {cal.world_view})")


def _dot_grid(size: tuple[int, int], pitch_mm: float, fiducials_text: str, asymmetric: bool) -> object:
    """The :class:`~skinkit.vision.dotgrid.DotGrid` the options describe (dots half a pitch
    across: detection does not depend on their size)."""
    from skinkit.vision.dotgrid import DotGrid, parse_fiducials

    kind, where = parse_fiducials(fiducials_text)
    return DotGrid(size[0], size[1], pitch_mm * 1e-3, 0.5 * pitch_mm * 1e-3, fiducials=where,
                   fiducial_kind=kind, asymmetric=asymmetric)


#: profiler options ``skinkit vision profile`` has flags for: keyword -> flag
PROFILE_FLAGS = {"spacing_px": "--spacing", "subset_px": "--subset"}


def profiler_kwargs(profiler: Any, values: Mapping[str, Any],
                    explicit: Collection[str] = ()) -> dict[str, Any]:
    """The options of ``values`` (keyword -> value) that ``profiler`` (a plugin class or object)
    declares in its optional ``options`` mapping (keyword -> description); a keyword in
    ``explicit`` (given on the command line) that it does not declare is refused naming the flag."""
    declared = getattr(profiler, "options", None)
    accepted = set(declared) if isinstance(declared, Mapping) else set()
    refused = [k for k in explicit if k not in accepted]
    if refused:
        flags = ", ".join(PROFILE_FLAGS.get(k, k) for k in refused)
        name = getattr(profiler, "name", profiler)
        raise SkinkitError(f"{flags}: profiler {name!r} does not take {', '.join(refused)} "
                           f"(its options: {', '.join(sorted(accepted)) or 'none'})")
    return {k: v for k, v in values.items() if k in accepted}


@vision.command("profile")
@click.argument("experiment", type=click.Path(dir_okay=False))
@click.option("--images", "images_name", default=None, help="image sequence to profile")
@click.option("--frame", default=0, show_default=True, type=click.IntRange(min=0),
              help="frame of the undeformed surface")
@click.option("--profiler", "profiler_name", default="patchwork", show_default=True)
@click.option("--spacing", "spacing_px", default=12, show_default=True, type=click.IntRange(1, 4096),
              help="grid step [px]")
@click.option("--subset", "subset_px", default=31, show_default=True, type=click.IntRange(8, 4096),
              help="subset side [px]")
@click.option("--name", "out_name", default="profile", show_default=True,
              callback=name_callback("profile name"), help="name of the stored profile")
@click.option("--plot", "plot_path", default=None, type=click.Path(dir_okay=False),
              help="also save a figure (height and ISU maps) to this PNG")
@click.option("--overwrite", is_flag=True, help="replace a profile of that name already stored (and --plot)")
def profile_cmd(experiment: str, images_name: str | None, frame: int, profiler_name: str,
                spacing_px: int, subset_px: int, out_name: str, plot_path: str | None,
                overwrite: bool) -> None:
    """Profile the surface automatically and store the point cloud in EXPERIMENT."""
    import numpy as np

    from skinkit import registry
    from skinkit.store import open_experiment

    with open_experiment(experiment) as exp:  # read only: a refused profile leaves the file as it was
        if out_name in exp.profile_names() and not overwrite:   # refused before profiling, not after
            raise SkinkitError(f"{experiment} already holds a profile named {out_name!r}; give another "
                               "--name, or --overwrite to replace it")
        if plot_path and os.path.exists(plot_path) and not overwrite:
            raise SkinkitError(f"--plot {plot_path}: already exists (an earlier figure); give another path, "
                               "or --overwrite to replace it")
        rig = exp.read_rig()
        seq = _images(exp, images_name, of_skin=True)
    ctx = click.get_current_context()
    explicit = [k for k in PROFILE_FLAGS
                if ctx.get_parameter_source(k) in (ParameterSource.COMMANDLINE, ParameterSource.ENVIRONMENT)]
    kwargs = profiler_kwargs(registry.load("skinkit.profilers", profiler_name),
                             {"spacing_px": spacing_px, "subset_px": subset_px}, explicit)
    prof = registry.create("skinkit.profilers", profiler_name, **kwargs)
    from skinkit.cli._progress import progress

    with progress(stage=f"profiling with {profiler_name}"):
        sp = prof.profile(seq, rig, frame=frame)
    with open_experiment(experiment, mode="a") as exp:
        exp.write_profile(out_name, sp)
    if plot_path:
        from skinkit.vision.plots import plot_profile

        plot_profile(sp, plot_path, title=f"{experiment}: {out_name}")
        click.echo(f"figure saved to {plot_path}")
    isu = "" if sp.uncertainty_px is None else f", mean ISU {np.mean(sp.uncertainty_px):.2f} px"
    click.echo(f"profile {out_name!r}: {sp.n_points} points{isu}; stored in {experiment}")


@vision.command("track-3d")
@click.argument("experiment", type=click.Path(dir_okay=False))
@click.option("--images", "images_name", default=None, help="image sequence to track through")
@click.option("--profile", "profile_name", default="profile", show_default=True)
@click.option("--tracker", "tracker_name", default="gn", show_default=True)
@click.option("--subset", "subset_px", default=41, show_default=True, type=click.IntRange(8, 4096),
              help="subset side [px]")
@click.option("--name", "out_name", default=None, callback=name_callback("track name"),
              help="name of the stored track (default: the images')")
@click.option("--overwrite", is_flag=True, help="replace a track of that name already stored")
def track3d_cmd(experiment: str, images_name: str | None, profile_name: str, tracker_name: str,
                subset_px: int, out_name: str | None, overwrite: bool) -> None:
    """Track the profiled points through an image sequence in 3D; store the SurfaceTrack."""
    from skinkit import registry
    from skinkit.store import open_experiment
    from skinkit.vision.tracking3d import track_3d

    with open_experiment(experiment) as exp:  # read only: a refused track leaves the file as it was
        rig = exp.read_rig()
        seq = _images(exp, images_name, of_skin=True)
        if profile_name not in exp.profile_names():
            raise SkinkitError(f"no profile {profile_name!r} in {experiment}; "
                               "run `skinkit vision profile` first")
        sp = exp.read_profile(profile_name)
        name = out_name if out_name is not None else seq.name  # type: ignore[attr-defined]
        if name in exp.track_names() and not overwrite:  # refused before tracking, not after
            raise SkinkitError(f"{experiment} already holds a track named {name!r}; give another "
                               "--name, or --overwrite to replace it")
    tracker = registry.create("skinkit.trackers", tracker_name)
    from skinkit.cli._progress import progress

    with progress(transient=True) as bar:
        track, _ = track_3d(rig, seq, sp.points, tracker, subset_px,  # type: ignore[arg-type]
                            progress=lambda k, n: bar.update("tracking frames", k / n if n else None,
                                                             f"{k}/{n} frames"))
    with open_experiment(experiment, mode="a") as exp:
        exp.write_track(name, track)
    ok = track.valid.all(axis=1).sum()
    click.echo(f"track {name!r}: {track.n_points} points x {track.n_frames} frames, "
               f"{ok} valid in every frame; stored in {experiment}")
