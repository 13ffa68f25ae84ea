"""``skinkit vision``: calibrate a rig, profile the surface, track points in 2D and 3D."""

from __future__ import annotations

import json
import math

import click

from skinkit.errors import SkinkitError


@click.group("vision")
def vision() -> None:
    """Stereo vision: calibration, surface profiling, 2D and 3D tracking."""


def _num(x: float) -> float | None:
    return None if not math.isfinite(float(x)) else float(x)


@vision.command("track")
@click.argument("ref_image", type=click.Path(dir_okay=False))
@click.argument("cur_image", type=click.Path(dir_okay=False))
@click.option("--points", "points_csv", required=True, type=click.Path(dir_okay=False),
              help="CSV with header x_px,y_px: points in REF_IMAGE (origin: centre of the top-left pixel)")
@click.option("--subset", "subset_px", default=64, show_default=True, help="subset side [px]")
@click.option("--tracker", "tracker_name", default="gn", show_default=True,
              help="tracker plugin (skinkit.trackers)")
@click.option("--search", "search_px", default=None, type=int, help="integer search radius [px]")
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
            for p, d, q, v, r in zip(pts, res.displacement_px, res.quality, res.valid, res.reason)]
    if as_json:
        click.echo(json.dumps({"points": rows}, indent=1))
        return
    for row in rows:
        if row["valid"]:
            click.echo(f"({row['x_px']:.2f}, {row['y_px']:.2f}): dx {row['dx_px']:+.4f} px, "
                       f"dy {row['dy_px']:+.4f} px, quality {row['quality']:.3f}")
        else:
            click.echo(f"({row['x_px']:.2f}, {row['y_px']:.2f}): invalid: {row['reason']}")
    n_ok = sum(r["valid"] for r in rows)
    click.echo(f"{n_ok} of {len(rows)} points tracked with {tracker_name}")
