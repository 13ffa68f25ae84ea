"""The image sequences: their size and frames, and the first and last frame of each camera as
thumbnails (only those two frames are read, whatever the sequence's length)."""

from __future__ import annotations

import numpy as np

from skinkit.report.common import Section, array_uri, e, img, note, plural, slug, t, table, warn_list
from skinkit.store import layout as L
from skinkit.store.experiment import Experiment

#: thumbnails are reduced to at most this width [px]
THUMB_WIDTH = 320


def _thumb(frame: np.ndarray) -> np.ndarray:
    """A grey frame ``(H, W)`` of any depth as an ``(h, w, 3)`` uint8 thumbnail, contrast
    stretched between its 0.5 and 99.5 percentiles."""
    step = max(1, int(np.ceil(frame.shape[1] / THUMB_WIDTH)))
    x = np.asarray(frame[::step, ::step], float)
    lo, hi = np.nanpercentile(x, [0.5, 99.5]) if x.size else (0.0, 1.0)
    y = np.clip((x - lo) / (hi - lo if hi > lo else 1.0), 0, 1)
    g = np.nan_to_num(y * 255).astype(np.uint8)
    return np.repeat(g[:, :, None], 3, axis=2)


def _frames(exp: Experiment, name: str, n: int) -> list[tuple[int, np.ndarray]]:
    """Frames 0 and n−1 ``(C, H, W)``, read alone from the file (a sequence may be gigabytes)."""
    ds = exp._f[f"{L.IMAGES}/{name}/frames"]   # read-only slicing: the reader API loads every frame
    keep = sorted({0, n - 1})
    return [(k, np.asarray(ds[k])) for k in keep]


def _sequence(exp: Experiment, info: dict) -> str:
    name, n = info["name"], info["frames"]
    head = f'<div class="item" id="images-{slug(name)}"><h3>{e(name)}</h3>'
    warns = [] if info["complete"] else ["The sequence is incomplete: its writer did not close it."]
    if n == 0:
        return head + warn_list(warns) + note("No frame committed.") + "</div>"
    out = head + warn_list(warns)
    for k, frames in _frames(exp, name, n):
        for c, cam in enumerate(info["cameras"]):
            out += img(array_uri(_thumb(frames[c])), f"{name}: camera {cam}, frame {k}")
    return out + "</div>"


def section(exp: Experiment) -> Section:
    """The image sequences (``/images``)."""
    infos = [exp.image_info(n) for n in exp.image_names()]
    if not infos:
        return Section("images", "Images", None, "omitted: the file holds no image sequence")
    rows = [[t(i["name"], i["name"]), t(i["frames"], i["frames"]), t(", ".join(map(str, i["cameras"]))),
             t(f"{i['image_size'][0]}×{i['image_size'][1]}"), t(i["dtype"]),
             t("yes" if i["complete"] else "no")] for i in infos]
    body = (table(["sequence", "frames", "cameras", "size [px]", "type", "complete"], rows)
            + "<p>First and last frame of each camera (contrast stretched).</p>"
            + '<div class="thumbs">' + "".join(_sequence(exp, i) for i in infos) + "</div>")
    return Section("images", "Images", body,
                   f"{plural(len(infos), 'sequence')}, {sum(i['frames'] for i in infos)} frames")
