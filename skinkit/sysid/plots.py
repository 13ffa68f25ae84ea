"""Figures of an identification (matplotlib, Agg): thesis Figure 4-12 and residual plots."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from skinkit.sysid.diagnostics import ResidualDiagnostics
from skinkit.sysid.lti import kernel


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_identification(model: Any, force_N: np.ndarray, position_m: np.ndarray,
                        path: str | Path, window_s: float | None = None) -> Path:
    """Four panels like thesis Fig. 4-12: (a) input force, (b) IRF measured (95 % band) and
    fitted, (c) static nonlinearity (Wiener/Hammerstein) or predicted-vs-measured (linear),
    (d) predicted and measured output. ``model`` is a Linear, Wiener or Hammerstein model;
    when its linear part is not a valid damped sinusoid, the IRF's own prediction is shown.
    ``window_s`` [s] of the record after the burn-in are shown in (a) and (d) (default: the
    whole record, so that drift or a change of behaviour is not hidden). Returns the
    written file."""
    plt = _plt()
    lin = getattr(model, "linear", model)
    rate = lin.rate_hz
    f = np.asarray(force_N, float)
    y = np.asarray(position_m, float)
    if lin.valid:
        yp = model.predict(f)
    else:  # no simulatable parametric model: show what the non-parametric IRF predicts
        yp = lin.irf.predict(f - f.mean()) + y.mean()
        model = lin
    t = np.arange(f.size) / rate
    b = lin.burn_in
    if window_s is None:
        window_s = f.size / rate
    w = slice(b, min(f.size, b + int(window_s * rate)))
    fig, ax = plt.subplots(2, 2, figsize=(10, 7))
    ax[0, 0].plot(t[w], f[w], lw=0.8)
    ax[0, 0].set(title="(a) input force", xlabel="time [s]", ylabel="force [N]")
    irf = lin.irf
    lo, hi = irf.bounds()
    ax[0, 1].fill_between(irf.lags_s, lo, hi, color="C0", alpha=0.25, label="95 % bound")
    ax[0, 1].plot(irf.lags_s, irf.h, color="C0", lw=1, label="measured")
    d = lin.damped
    nn = irf.n_neg
    if lin.valid:
        fit = kernel(d.A1, d.A2, d.A3, irf.h.size - nn, rate, lin.hold)
        ax[0, 1].plot(irf.lags_s[nn:], fit, color="C3", lw=1, label="damped sinusoid")
    ax[0, 1].set(title=f"(b) IRF (rank {irf.rank})", xlabel="lag [s]", ylabel="h [m/(N s)]")
    ax[0, 1].legend(fontsize=8)
    nl = getattr(model, "nonlinearity", None)
    if nl is not None and hasattr(model, "intermediate"):
        x = model.intermediate(f)
        ax[1, 0].plot(x[b:], y[b:] * 1e3, ",", color="C0", alpha=0.4, label="measured")
        xs = np.linspace(x[b:].min(), x[b:].max(), 200)
        ax[1, 0].plot(xs, nl(xs) * 1e3, color="C3", label="fitted")
        ax[1, 0].set(title="(c) static nonlinearity", xlabel="linear prediction x [N]",
                     ylabel="position [mm]")
    elif nl is not None:
        fs = np.linspace(f.min(), f.max(), 200)
        ax[1, 0].plot(fs, nl(fs) * 1e3, color="C3")
        ax[1, 0].set(title="(c) input nonlinearity (Hammerstein)", xlabel="force [N]",
                     ylabel="g(f) [mm]")
    else:
        ax[1, 0].plot(yp[b:] * 1e3, y[b:] * 1e3, ",", alpha=0.4)
        lim = [min(yp[b:].min(), y[b:].min()) * 1e3, max(yp[b:].max(), y[b:].max()) * 1e3]
        ax[1, 0].plot(lim, lim, color="C3", lw=1)
        ax[1, 0].set(title="(c) predicted vs measured", xlabel="predicted [mm]",
                     ylabel="measured [mm]")
    ax[1, 1].plot(t[w], y[w] * 1e3, color="C0", lw=0.8, label="measured")
    ax[1, 1].plot(t[w], yp[w] * 1e3, color="C3", lw=0.8, label="predicted")
    ax[1, 1].set(title="(d) output", xlabel="time [s]", ylabel="position [mm]")
    ax[1, 1].legend(fontsize=8)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def plot_residuals(diag: ResidualDiagnostics, path: str | Path, title: str = "") -> Path:
    """Residual autocorrelation and input-residual cross-correlation with their 95 % band,
    VAF per frequency band and per output-amplitude band."""
    plt = _plt()
    fig, ax = plt.subplots(2, 2, figsize=(10, 7))
    for a, c, name in ((ax[0, 0], diag.autocorr, "residual autocorrelation"),
                       (ax[0, 1], diag.crosscorr, "input-residual cross-correlation")):
        a.plot(diag.lags_s, c, lw=0.8)
        a.axhspan(-diag.bound, diag.bound, color="0.8", alpha=0.6, label="95 % white band")
        nz = diag.lags_s != 0
        top = 1.3 * max(3 * diag.bound, float(np.max(np.abs(c[nz]))))
        a.set(title=name, xlabel="lag [s]", ylim=(-top, top))  # lag 0 of the autocorrelation is 1
        a.legend(fontsize=8)
    e = diag.band_edges_hz
    labels = [f"{lo:g}-{hi:g}" for lo, hi in zip(e[:-1], e[1:], strict=True)]
    ax[1, 0].bar(labels, diag.vaf_by_band_pct)
    ax[1, 0].set(title="VAF per frequency band", xlabel="band [Hz]", ylabel="VAF [%]")
    q = diag.amplitude_edges_m * 1e3
    labels = [f"{lo:.3g}-{hi:.3g}" for lo, hi in zip(q[:-1], q[1:], strict=True)]
    ax[1, 1].bar(labels, diag.vaf_by_amplitude_pct)
    ax[1, 1].set(title="VAF per output amplitude band", xlabel="position [mm]", ylabel="VAF [%]")
    ax[1, 1].tick_params(axis="x", labelrotation=30, labelsize=7)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def plot_incremental(table: list[dict[str, Any]], path: str | Path) -> Path:
    """K, I, B and VAF against mean position, ascending and descending (thesis Fig. 4-14)."""
    plt = _plt()
    fig, ax = plt.subplots(2, 2, figsize=(10, 7))
    keys = (("K_N_per_m", "stiffness K [N/m]"), ("I_kg", "inertia I [kg]"),
            ("B_Ns_per_m", "damping B [N s/m]"), ("vaf_linear_pct", "VAF [%]"))
    for a, (k, label) in zip(ax.flat, keys, strict=True):
        for direction, marker in (("up", "o-"), ("down", "s--")):
            rows = [r for r in table if r["direction"] == direction]
            a.plot([r["position_mean_m"] * 1e3 for r in rows], [r[k] for r in rows], marker,
                   label=direction, ms=4)
        a.set(xlabel="mean position [mm]", ylabel=label)
        a.legend(fontsize=8)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def plot_comparison(rows: list[dict[str, Any]], band_edges_hz: np.ndarray,
                    path: str | Path) -> Path:
    """VAF per frequency band and whiteness of each model's residual, side by side (rows
    from :func:`skinkit.sysid.diagnostics.compare`)."""
    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    e = np.asarray(band_edges_hz)
    labels = [f"{lo:g}-{hi:g}" for lo, hi in zip(e[:-1], e[1:], strict=True)]
    width = 0.8 / max(len(rows), 1)
    for k, r in enumerate(rows):
        ax[0].bar(np.arange(len(labels)) + k * width, r["vaf_by_band_pct"], width,
                  label=f"{r['model']} ({r['vaf_pct']:.2f} %)")
    ax[0].set_xticks(np.arange(len(labels)) + 0.4 - width / 2, labels)
    ax[0].set(title="VAF per frequency band", xlabel="band [Hz]", ylabel="VAF [%]")
    ax[0].legend(fontsize=8)
    names = [r["model"] for r in rows]
    ax[1].bar(names, [100 * r["whiteness_outside"] for r in rows], label="autocorrelation")
    ax[1].axhline(5.0, color="0.5", ls="--", label="white (5 %)")
    ax[1].set(title="residual lags outside the 95 % band", ylabel="% of lags")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out
