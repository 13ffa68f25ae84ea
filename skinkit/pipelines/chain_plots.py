"""The demo's closing figure: every step against the truth, drawn once the truth may be read."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from skinkit.store import open_experiment


def _num(v: Any) -> str:
    return v if isinstance(v, str) else ("-" if v is None else f"{v:.4g}")


def truth_figure(out: Path, summary: dict[str, Any], table: list[dict[str, Any]]) -> Path:
    """``out/truth.png``: (a) a robot record (tip motion and force of in-plane 0°); (b) every
    tracked displacement against the truth's (subset-mean) motion; (c) the identified parameters
    relative to the truth, without and with the named effect; (d) the named effect's values."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from skinkit.pipelines.chain_truth import SESSION, tracked_against_truth

    fig, ax = plt.subplots(2, 2, figsize=(11, 8.5), constrained_layout=True)
    with open_experiment(out / SESSION) as exp:
        names = exp.record_names()
        rec_name = "in_plane_000" if "in_plane_000" in names else names[0]
        rec = exp.read_record(rec_name)
    a = ax[0, 0]
    axis = int(np.argmax(np.ptp(rec.tip_position, axis=0)))
    a.plot(rec.time_s, rec.tip_position[:, axis] * 1e3, lw=0.8, color="C0")
    a.set_xlabel("time [s]")
    a.set_ylabel(f"tip position {'xyz'[axis]} [mm]", color="C0")
    b = a.twinx()
    b.plot(rec.time_s, rec.tip_force[:, axis] * 1e3, lw=0.5, color="C3", alpha=0.7)
    b.set_ylabel(f"tip force {'xyz'[axis]} [mN]", color="C3")
    a.set_title(f"(a) robot record {rec_name} (robot frame)")

    a = ax[0, 1]
    for k, (name, (meas, true)) in enumerate(tracked_against_truth(out, windowed=True).items()):
        m, t = meas.ravel() * 1e6, true.ravel() * 1e6
        a.plot(t, m - t, ".", ms=1.5, alpha=0.4, color=f"C{k}", label=name)
    a.axhline(0, color="k", lw=0.8)
    a.set_xlabel("true displacement, subset mean [µm]")
    a.set_ylabel("tracked minus true [µm]")
    a.set_title("(b) 3D tracks against the truth (x, y, z components)")
    a.legend(markerscale=6, fontsize=8)

    a = ax[1, 0]
    rows = {(r["step"], r["result"]): r for r in table}
    params = [r["result"] for r in table if r["step"] == "identify"]
    if params:
        x = np.arange(len(params))
        without = [rows[("identify", p)]["error"] or 0.0 for p in params]
        a.bar(x - 0.2, without, 0.4, label="thesis model (no pre-stress)")
        named = [r for r in table if r["step"] == "diagnose" and "(with " in r["result"]]
        if named:
            with_ = {r["result"].split(" (with")[0]: r["error"] or 0.0 for r in named}
            a.bar(x + 0.2, [with_.get(p, np.nan) for p in params], 0.4,
                  label=f"with the named effect ({named[0]['result'].split('(with ')[1][:-1]})")
        a.axhline(0, color="k", lw=0.8)
        a.set_xticks(x, [p.split(".", 1)[1] for p in params])
        a.set_ylabel("error against the truth [%]")
        a.legend(fontsize=8)
    a.set_title("(c) identified skin parameters")

    a = ax[1, 1]
    a.axis("off")
    eff = [r for r in table if r["step"] == "diagnose" and "(with " not in r["result"]]
    cells = [[r["result"], _num(r["found"]), _num(r["truth"]), _num(r["error"]) + " " + r["error_unit"]
              if r["error"] is not None else "-"] for r in eff]
    if cells:
        t = a.table(cellText=cells, colLabels=["diagnosis", "found", "truth", "error"], loc="center")
        t.auto_set_font_size(False)
        t.set_fontsize(9)
        t.scale(1, 1.6)
    gap = summary.get("diagnose", {})
    a.set_title(f"(d) named: {', '.join(gap.get('named') or ['none'])}")
    path = out / "truth.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


__all__ = ["truth_figure"]
