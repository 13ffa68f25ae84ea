"""Helpers of the report tests: one experiment file holding every kind of result, built by the
commands a user runs (fast ones): a virtual-lab session of the lumped extension model, its fit and
gap diagnosis, images, an OpenCV calibration and a DIC track imported from files written to disk
as other tools write them; plus the lumped system identifications ``skinkit demo`` stores (linear
K, B, I and Wiener, from simulated stochastic records), through the same library calls.

Known by construction, for the tests to check the report against: the cameras' centres, the
track's displacement field and the stored reprojection errors.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from click.testing import CliRunner

REPO = Path(__file__).resolve().parents[2]
MODEL = REPO / "docs" / "models" / "extension_relaxation_lumped.toml"

#: the cameras: name -> centre in the world frame [mm]; both look at the origin
CENTRES_MM = {"cam0": (-60.0, 5.0, 150.0), "cam1": (60.0, -5.0, 150.0)}
IMAGE_WH = (96, 64)
N_FRAMES = 3
#: the track: a 5 x 4 grid [mm] stretched along x by STRAIN and narrowed along y (Poisson 0.3)
#: in TRACK_FRAMES frames, linearly in time; point MISSING_POINT is not seen in frame 2
STRAIN = 0.05
TRACK_FRAMES = 6
MISSING = (7, 2)
#: reprojection errors stored by the stereo step's calibration [px]
REPROJECTION = {"reprojection_rms_px": 0.121, "per_camera_rms_px": [0.113, 0.129]}


def _run(*args: str) -> str:
    from skinkit.cli import cli

    res = CliRunner().invoke(cli, list(args), catch_exceptions=False)
    assert res.exit_code == 0, res.output
    return res.output


def look_at(centre: np.ndarray) -> np.ndarray:
    """World → camera rotation of a camera at ``centre`` looking at the origin (rows: x, y, z
    axes of the camera in the world; z along the view, y roughly down the world's -y)."""
    z = -centre / np.linalg.norm(centre)
    x = np.cross([0.0, -1.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.array([x, y, z])


def track_grid() -> tuple[np.ndarray, np.ndarray]:
    """Reference points ``(P, 3)`` [mm] and positions ``(P, F, 3)`` [mm] of the imposed field."""
    xs, ys = np.meshgrid(np.linspace(-10, 10, 5), np.linspace(-6, 6, 4))
    ref = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    s = np.linspace(0.0, 1.0, TRACK_FRAMES)
    u = np.zeros((len(ref), TRACK_FRAMES, 3))
    u[:, :, 0] = STRAIN * ref[:, :1] * s
    u[:, :, 1] = -0.3 * STRAIN * ref[:, 1:2] * s
    return ref, ref[:, None, :] + u


def _images(d: Path) -> None:
    import cv2

    rng = np.random.default_rng(3)
    for cam in CENTRES_MM:
        (d / cam).mkdir()
        for k in range(N_FRAMES):
            speckle = cv2.GaussianBlur(rng.uniform(0, 255, IMAGE_WH[::-1]).astype(np.float32), (0, 0), 1.5)
            grey = np.clip(speckle * 2 - 128, 0, 255).astype(np.uint8)
            cv2.imwrite(str(d / cam / f"img_{k:03d}.png"), grey)


def _calibration(d: Path) -> list[str]:
    import cv2

    files = []
    for cam, c in CENTRES_MM.items():
        C = np.array(c)
        R = look_at(C)
        path = d / f"{cam}.yml"
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", IMAGE_WH[0])
        fs.write("image_height", IMAGE_WH[1])
        fs.write("camera_matrix", np.array([[120.0, 0, 48], [0, 121.0, 32], [0, 0, 1]]))
        fs.write("distortion_coefficients", np.array([[-0.05, 0.01, 0.0, 0.0, 0.0]]))
        fs.write("R", R)
        fs.write("T", (-R @ C).reshape(3, 1))
        fs.release()
        files.append(str(path))
    return files


def _tracks(d: Path) -> Path:
    ref, pos = track_grid()
    lines = ["frame,point,x_mm,y_mm,z_mm"]
    for k in range(TRACK_FRAMES):
        for i in range(len(ref)):
            if (i, k) == MISSING:
                continue
            lines.append(f"{k},{i}," + ",".join(f"{v:.9f}" for v in pos[i, k]))
    path = d / "dic_export.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def _lumped_fits(session: Path) -> dict[str, Any]:
    """What ``skinkit demo`` stores: the stochastic records and the linear and Wiener fits."""
    from skinkit.lab.lumped import LumpedTruth, stochastic_session
    from skinkit.schemas import FitResult, Parameter, ParameterSet
    from skinkit.store import open_experiment
    from skinkit.sysid import identify_linear, identify_wiener

    truth = LumpedTruth()
    lin_rec = stochastic_session(truth, wiener=False, seed=0)
    wie_rec = stochastic_session(truth, wiener=True, seed=1)
    ld, wd = identify_linear(lin_rec, robot=truth.robot).to_dict(), identify_wiener(wie_rec).to_dict()

    def fit(model: str, values: dict[str, tuple[float, str, float]], vaf: float,
            warns: list[str]) -> FitResult:
        params = ParameterSet(Parameter(k, v, u, lower=-math.inf) for k, (v, u, _) in values.items())
        se = [s for (_, _, s) in values.values()]
        return FitResult(model, params, objective=1 - vaf / 100, n_evaluations=lin_rec.n_samples,
                         covariance=np.diag(np.square(se)), extra={"vaf_pct": vaf, "warnings": warns},
                         message="objective = 1 - VAF/100 (fraction of output variance unexplained)")

    linear = fit("linear", {"K": (ld["K_N_per_m"], "N/m", ld["K_se_N_per_m"]),
                            "B": (ld["B_Ns_per_m"], "N s/m", ld["B_se_Ns_per_m"]),
                            "I": (ld["I_kg"], "kg", ld["I_se_kg"])}, ld["vaf_linear_pct"], ld["warnings"])
    wiener = fit("wiener", {"C1": (wd["C1_m"], "m", wd["C1_se_m"]),
                            "C2": (wd["C2_per_N"], "1", wd["C2_se_per_N"]),
                            "Is": (wd["Is_s2"], "1", wd["Is_se_s2"]), "Bs": (wd["Bs_s"], "s", wd["Bs_se_s"])},
                 wd["vaf_wiener_pct"], wd["warnings"] + ["ExampleWarning: a warning the report must show"])
    with open_experiment(session, "a") as exp:
        exp.write_record(lin_rec)
        exp.write_record(wie_rec)
        exp.write_fit("linear", linear)
        exp.write_fit("wiener", wiener)
        exp.write_calibration("stereo", dict(REPROJECTION))
    return {"linear": linear, "wiener": wiener}


class ReportDOM:
    """What the tests look at in a report's HTML (the file as written, or Chromium's DOM).

    Attributes:
        parts: ids of the top-level ``<section class="part">``, in order.
        ids: every id attribute, in order.
        imgs: ``(src, alt, part id)`` of every ``<img>``.
        contents: ``(class, text, href)`` of each item of the contents list.
        refs: every ``src``/``href`` value, and the tags that load something (link, iframe, ...).
        h2: the texts of the ``<h2>`` headings.
    """

    LOADERS = {"link", "iframe", "object", "embed", "frame", "base", "audio", "video", "source"}

    # C901: mccabe counts the three small handlers of the inline HTML parser (which fill this
    # object) as branches of __init__; each handler alone is simple.
    def __init__(self, text: str) -> None:  # noqa: C901
        from html.parser import HTMLParser

        self.parts: list[str] = []
        self.ids: list[str] = []
        self.imgs: list[tuple[str, str, str | None]] = []
        self.contents: list[tuple[str, str, str | None]] = []
        self.refs: list[str] = []
        self.h2: list[str] = []
        dom = self
        stack: list[str | None] = []
        state: dict[str, Any] = {"li": None, "h2": None}

        class P(HTMLParser):
            def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
                a = dict(attrs)
                if a.get("id"):
                    dom.ids.append(a["id"])
                for k in ("src", "href"):
                    if a.get(k) is not None:
                        dom.refs.append(a[k])
                if tag in ReportDOM.LOADERS:
                    dom.refs.append(f"<{tag}>")
                if tag == "section":
                    part = a.get("id") if "part" in (a.get("class") or "").split() else None
                    if part:
                        dom.parts.append(part)
                    stack.append(part or (stack[-1] if stack else None))
                elif tag == "img":
                    dom.imgs.append((a.get("src") or "", a.get("alt") or "", stack[-1] if stack else None))
                elif tag == "li" and any(x == "contents" for x in state.get("ol", [])):
                    state["li"] = [a.get("class") or "", "", None]
                elif tag == "ol":
                    state.setdefault("ol", []).append(a.get("class"))
                elif tag == "a" and state["li"] is not None:
                    state["li"][2] = a.get("href")
                elif tag == "h2":
                    state["h2"] = ""

            def handle_endtag(self, tag: str) -> None:
                if tag == "section" and stack:
                    stack.pop()
                elif tag == "li" and state["li"] is not None:
                    dom.contents.append(tuple(state["li"]))
                    state["li"] = None
                elif tag == "ol" and state.get("ol"):
                    state["ol"].pop()
                elif tag == "h2" and state["h2"] is not None:
                    dom.h2.append(state["h2"])
                    state["h2"] = None

            def handle_data(self, data: str) -> None:
                if state["li"] is not None:
                    state["li"][1] += data
                if state["h2"] is not None:
                    state["h2"] += data

        P().feed(text)


def png_of(src: str) -> np.ndarray:
    """The image of a ``data:image/png;base64,`` URI, decoded (fails the test if it is not a PNG)."""
    import base64
    import io

    from matplotlib.image import imread

    head = "data:image/png;base64,"
    assert src.startswith(head), src[:60]
    raw = base64.b64decode(src[len(head):], validate=True)
    assert raw[:8] == b"\x89PNG\r\n\x1a\n"
    return imread(io.BytesIO(raw), format="png")


#: the report's sections, in order, for a file holding every kind of result
ALL_PARTS = ["session", "records", "lumped", "calibration", "images", "profiles", "tracks", "fits", "gaps"]
#: the sections that carry figures (the others are tables and words)
FIGURED = ["records", "calibration", "images", "profiles", "tracks", "fits", "gaps"]


def build_session(d: Path) -> dict[str, Any]:
    """The experiment file with every kind of result (module docstring), in folder ``d``."""
    s = d / "session.h5"
    _run("lab", "session", str(MODEL), "--out", str(s), "--truth-out", str(d / "truth.json"), "--seed", "1")
    _run("fit", str(MODEL), str(s), "--out", str(d / "fit"))
    _run("gap", "diagnose", str(MODEL), str(s), "--out", str(d / "gap"))
    _images(d)
    _run("import-images", str(s), "--name", "speckle", "--camera", "cam0", str(d / "cam0"),
         "--camera", "cam1", str(d / "cam1"))
    _run("import-calibration", str(s), *_calibration(d), "--unit", "mm")
    _run("import-tracks", str(s), str(_tracks(d)), "--name", "dic", "--fps", "5")
    lumped = _lumped_fits(s)
    return {"path": s, "dir": d, "lumped": lumped}
