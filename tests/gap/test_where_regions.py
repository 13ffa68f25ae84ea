"""The ``region`` axis from the model's geometry: the two-pad partition, the probe's polar ones.

Two-pad sessions are built from numpy as in ``test_where``: one protocol whose drive is the
moving pad's position along x (the same trapezoid), a predicted pad force, and tracked points on
a grid over the two-pad surface of the shipped model (8 mm pads, 28.5 mm apart), none on a pad.
The prediction is the truth, plus an excess where a test wants one.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from skinkit.errors import SkinkitError
from skinkit.fem.twopad_regions import (
    BEHIND_FIXED,
    BEHIND_MOVING,
    BESIDE_MINUS,
    BESIDE_PLUS,
    EDGE_FRACTION,
    PAD_EDGES,
    twopad_partition,
)
from skinkit.forward import read_description, region_partitions
from skinkit.gap.html import render_html
from skinkit.gap.where import cell_chi2, locate, samples
from skinkit.schemas import Channel, ChannelPrediction, Observations, Prediction, ProtocolObservations
from skinkit.schemas.protocol import Protocol
from skinkit.schemas.regions import RegionPartition, polar_partitions
from tests.gap.test_where import session, trapezoid

ROOT = Path(__file__).resolve().parents[2]
TWOPAD = ROOT / "skinkit" / "data" / "models" / "extension_dic_twopad.toml"
PAD, GAP = 0.008, 0.0285                      # the shipped model's geometry [m]
H, E = GAP / 2, GAP / 2 + PAD                 # facing and outer edges' |x| [m]
EDGE = EDGE_FRACTION * PAD                    # width of the pad-edge region [m]
RATE, T, F = 100.0, 2000, 21
SF, SN = 4e-3, 4e-6                           # force [N] and tracking [m] noise


def grid() -> np.ndarray:
    """``(P, 3)`` [m]: every 3 mm over 88 x 42 mm, offset so that no point lies on a region's edge,
    without the points on a pad (tracking does not see skin under a glued pad)."""
    x, y = np.meshgrid(np.arange(-43.25e-3, 44e-3, 3e-3), np.arange(-19.75e-3, 20e-3, 3e-3), indexing="ij")
    pts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    on_pad = (np.abs(pts[:, 1]) <= PAD / 2) & (np.abs(pts[:, 0]) >= H) & (np.abs(pts[:, 0]) <= E)
    return pts[~on_pad]


def twopad_session(seed: int, excess=None):
    """(observations, prediction) of one pull; ``excess(ref, drive_at_frames)`` returns an added
    misfit of the predicted points ``(P, F, 3)`` [m]."""
    rng = np.random.default_rng(seed)
    ref = grid()
    P = ref.shape[0]
    t = np.arange(T) / RATE
    drv = trapezoid(t)
    fr = np.arange(F) * (T / RATE / F)
    dfr = drv[np.searchsorted(t, fr)]
    pos = np.zeros((T, 3))
    pos[:, 0] = 3e-3 * drv
    force = np.zeros((T, 3))
    force[:, 0] = 0.1 * drv
    u = np.zeros((P, F, 3))
    # the skin between the pads follows the pull, the rest a little
    u[:, :, 0] = 1e-3 * dfr[None, :] * np.clip((ref[:, :1] + H) / GAP, 0.0, 1.0)
    X = ref[:, None, :] + u + rng.normal(0, SN, (P, F, 3))
    obs = {"pull": ProtocolObservations(Protocol("pull"), {
        "tip_position": Channel("tip_position", t, pos, noise=1e-6, noise_source="declared"),
        "tip_force": Channel("tip_force", t, force + rng.normal(0, SF, (T, 3)), noise=SF,
                             noise_source="declared"),
        "points": Channel("points", fr, X, noise=SN, noise_source="tracker", reference=X[:, 0],
                          reference_frame=0)})}
    ppts = X[:, :1] + u
    if excess is not None:
        ppts = ppts + excess(ref, dfr)
    pred = {"pull": {"tip_force": ChannelPrediction(force), "points": ChannelPrediction(ppts)}}
    return Observations(obs, None, "synthetic"), Prediction(pred, inputs={"pull": "tip_position"})


def behind_moving(ref: np.ndarray, dfr: np.ndarray) -> np.ndarray:
    """A 3σ misfit along the pull, growing with it, of the points behind the moving pad only."""
    out = np.zeros((ref.shape[0], F, 3))
    sel = ref[:, 0] > E + EDGE
    out[sel, 1:, 0] = 3.0 * SN * dfr[1:]
    return out


def twopad_regions():
    return region_partitions(read_description(TWOPAD))


def part(g, name):
    return [c for c in g.cells if c.axis == "region" and c.partition == name]


# ---------------------------------------------------------------------------------- the partition
def test_twopad_cells_follow_the_pads():
    d = EDGE
    pts = np.array([[0.0, 0.0], [-H + d + 1e-4, 0.0], [H - d - 1e-4, 0.0],       # mid-gap, both ends
                    [0.0, PAD], [0.0, -PAD], [E + 5e-3, 0.0], [E + 5e-3, 15e-3],  # beside, behind
                    [-E - 5e-3, -15e-3], [H - 0.5 * d, 0.0], [E + 0.5 * d, 1e-3],  # behind fixed, edges
                    [H + PAD / 2, 0.0], [E + 0.8 * d, PAD / 2 + 0.8 * d], [np.nan, 0.0]])
    rp = twopad_partition(pts, PAD, GAP)
    assert rp.name == "twopad" and len(rp.cells) == 4 + 5
    between = rp.cells[:4]
    assert all(c.startswith("between pads") for c in between)
    # x = 0 is the edge between bands 2 and 3: the band above, as on a radial band's edge
    assert rp.labels == (between[2], between[0], between[3], BESIDE_PLUS, BESIDE_MINUS, BEHIND_MOVING,
                         BEHIND_MOVING, BEHIND_FIXED, PAD_EDGES, PAD_EDGES, PAD_EDGES, BEHIND_MOVING, None)
    # the bands share what the edge regions leave of the gap, fixed pad first
    assert between[0] == f"between pads 1/4 (x {-1e3 * (H - d):.1f} to {-0.5e3 * (H - d):.1f} mm)"
    # the shipped model's geometry is read from its description
    got = twopad_regions()(pts)
    assert [p.name for p in got] == ["radius", "sector", "twopad"] and got[2] == rp


def test_residual_behind_the_moving_pad_is_found_there():
    obs, pred = twopad_session(3, behind_moving)
    g = locate(obs, pred, regions=twopad_regions())
    cells = part(g, "twopad")
    target = next(c for c in cells if c.label == BEHIND_MOVING)
    assert target.significant and g.significant
    assert max(cells, key=lambda c: c.share) is target
    assert target.share > 0.8                           # most of the partition's excess
    for c in cells:
        if c.label.startswith("between pads"):
            assert not c.significant, c
    assert not any(c.significant for c in cells if c is not target)
    assert [c for c in g.ranked() if c.partition == "twopad"][0] is target
    # the same cells evaluated on the exact prediction fall back to the noise
    key = ("region", BEHIND_MOVING)
    before = cell_chi2(obs, pred, [key], regions=twopad_regions())[key]
    after = cell_chi2(obs, twopad_session(3)[1], [key], regions=twopad_regions())[key]
    assert before[0] == pytest.approx(target.chi2)
    assert after[0] / after[1] < 1 + 5 * math.sqrt(2 / after[1]) < target.chi2_per_dof


def test_twopad_cells_add_up_to_the_region_axis():
    obs, pred = twopad_session(4, behind_moving)
    g = locate(obs, pred, regions=twopad_regions(), n_params=2)
    pts = sum(float(s.z @ s.z) for s in samples(obs, pred) if s.channel == "points")
    for name in ("radius", "sector", "twopad"):
        assert sum(c.chi2 for c in part(g, name)) == pytest.approx(pts, rel=1e-12), name
    sh = [c.share for c in part(g, "twopad")]
    assert sum(sh) == pytest.approx(1.0)
    # every cell of every partition is one more member of one Holm family: a partition more,
    # no cell less
    assert len(g.cells) == len(locate(obs, pred, n_params=2).cells) + len(part(g, "twopad"))
    assert {c.partition for c in g.axis("region")} == {"radius", "sector", "twopad"}


def test_null_twopad_session_has_no_significant_region():
    g = locate(*twopad_session(5), regions=twopad_regions())
    assert not any(c.significant for c in g.axis("region"))


# --------------------------------------------------------------------------------- probe geometry
@pytest.mark.parametrize("model", ["invivo_quick.toml", "phantom_cube_box.toml"])
def test_probe_geometry_keeps_radius_and_sector(model):
    spec = read_description(ROOT / "docs" / "models" / model)
    assert (spec.get("geometry") or {}).get("kind", "disc") in ("disc", "block")
    obs, pred = session(13)
    by_model = locate(obs, pred, regions=region_partitions(spec))
    default = locate(obs, pred)
    assert [c.to_dict() for c in by_model.cells] == [c.to_dict() for c in default.cells]
    assert {c.partition for c in by_model.axis("region")} == {"radius", "sector"}


def test_a_lumped_model_has_no_regions():
    assert region_partitions({"model": {"kind": "lumped"}}) is None


# ------------------------------------------------------------------------------------- bad input
def test_labels_that_do_not_match_the_points_are_one_line():
    obs, pred = twopad_session(6)

    def short(points):
        return [RegionPartition("halves", ("left", "right"), ("left",) * (len(points) - 1))]

    with pytest.raises(SkinkitError) as e:
        locate(obs, pred, regions=short)
    msg = str(e.value)
    assert "halves" in msg and f"{len(points_of(obs))} reference points" in msg and "\n" not in msg
    with pytest.raises(SkinkitError, match="not among its cells") as e:
        RegionPartition("halves", ("left", "right"), ("left", "middle"))
    assert "\n" not in str(e.value)

    def clash(points):
        again = RegionPartition("again", ("sector 0-30 deg",), (None,) * len(points))
        return [*polar_partitions(points), again]

    with pytest.raises(SkinkitError, match="unique along the region axis"):
        locate(obs, pred, regions=clash)
    with pytest.raises(SkinkitError, match="RegionPartition"):
        locate(obs, pred, regions=lambda points: [("left", "right")])
    with pytest.raises(SkinkitError, match="region provider"):
        locate(obs, pred, regions="twopad")


def points_of(obs: Observations) -> np.ndarray:
    return obs["pull"].channel("points").reference


# ------------------------------------------------------------------------------ diagnosis, report
def test_every_locate_of_the_diagnosis_passes_the_models_regions():
    """``skinkit gap diagnose`` locates the residual, and compares cells before and after, on the
    model's own regions: every call passes them."""
    tree = ast.parse((ROOT / "skinkit" / "gap" / "diagnose.py").read_text(encoding="utf-8"))
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)
             and n.func.id in ("locate", "cell_chi2")]
    assert len(calls) >= 3
    for c in calls:
        assert any(k.arg == "regions" and ast.unparse(k.value) == "run.regions" for k in c.keywords), \
            ast.unparse(c)
    assert "regions=region_partitions(spec)" in ast.unparse(tree)


def test_html_lists_the_twopad_cells():
    obs, pred = twopad_session(3, behind_moving)
    g = locate(obs, pred, regions=twopad_regions())
    page = render_html({"gap": g.to_dict()})
    for c in part(g, "twopad"):
        assert c.label in page
    assert "region (twopad)" in page and "region (radius)" in page
