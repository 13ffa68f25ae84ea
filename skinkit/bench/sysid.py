"""``skinkit bench sysid``: Wiener identification time on a 5 s, 2 kHz record, and the
correlation/pseudo-inverse IRF against plain least squares on the full Toeplitz matrix."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np


def _best(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    """Fastest of ``repeat`` runs [s] and the last result."""
    best = np.inf
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return float(best), out


def run(repeat: int = 3, seed: int = 0, duration_s: float = 5.0,
        rate_hz: float = 2000.0) -> dict[str, Any]:
    """Run the benchmark; returns the figures as a JSON-ready dict."""
    from scipy.linalg import toeplitz

    from skinkit.sysid import estimate_irf, estimate_irf_lstsq, identify_wiener
    from skinkit.sysid.irf import correlations
    from skinkit.sysid.lti import SecondOrder, kernel
    from skinkit.sysid.simulate import simulate_record

    truth = SecondOrder(K=1450.0, B=4.76, I=0.0155 + 0.025)  # thesis Table 7 + robot mass
    rec = simulate_record(truth, duration_s=duration_s, rate_hz=rate_hz, mean_N=1.0, rms_N=0.5,
                          wiener=(8.6e-3, 0.51), seed=seed)
    t_wiener, w = _best(lambda: identify_wiener(rec.force_N, rec.position_m, rate_hz), repeat)
    memory = w.linear.irf.memory_s
    lin = simulate_record(truth, duration_s=duration_s, rate_hz=rate_hz, seed=seed)
    t_svd, irf = _best(lambda: estimate_irf(lin.force_N, lin.position_m, rate_hz, memory), repeat)
    t_ls, h_ls = _best(lambda: estimate_irf_lstsq(lin.force_N, lin.position_m, rate_hz, memory),
                       repeat)
    true = kernel(*truth.damped_sinusoid(), irf.h.size, rate_hz, "foh")
    rxx, _ = correlations(lin.force_N - lin.force_N.mean(), lin.force_N, irf.h.size)
    ev = np.linalg.eigvalsh(toeplitz(rxx))
    norm = float(np.linalg.norm(true))
    return {
        "record": {"duration_s": duration_s, "rate_hz": rate_hz, "samples": rec.force_N.size},
        "wiener_identification_s": t_wiener,
        "wiener_target_s": 0.5,
        "wiener_vaf_pct": w.vaf_wiener_pct,
        "irf_memory_s": memory,
        "irf_lags": int(irf.h.size),
        "irf_svd_mdl_s": t_svd,
        "irf_full_toeplitz_lstsq_s": t_ls,
        "speedup_vs_lstsq": t_ls / t_svd,
        "irf_error_svd_rel": float(np.linalg.norm(irf.h - true) / norm),
        "irf_error_lstsq_rel": float(np.linalg.norm(h_ls - true) / norm),
        "input_autocorrelation_condition": float(ev.max() / max(ev.min(), ev.max() * 1e-300)),
        "repeat": repeat,
    }


def run_limited(repeat: int = 3, seed: int = 0, threads: int = 1) -> dict[str, Any]:
    """:func:`run` with ``threads`` BLAS threads for both sides (0: the library default; 1
    avoids oversubscription on a shared machine); ``blas_threads`` says what applied."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional: without it the library default applies
        threadpool_limits = None
    if threads and threadpool_limits is not None:
        with threadpool_limits(limits=threads):
            r = run(repeat=repeat, seed=seed)
    else:
        r = run(repeat=repeat, seed=seed)
    r["blas_threads"] = threads if threadpool_limits is not None else 0
    return r


def summary_lines(r: dict[str, Any]) -> list[str]:
    """The figures of :func:`run` as lines of text."""
    return [f"record: {r['record']['duration_s']} s at {r['record']['rate_hz']:g} Hz "
            f"({r['record']['samples']} samples), IRF {r['irf_lags']} lags",
            f"Wiener identification: {r['wiener_identification_s']:.3f} s "
            f"(target {r['wiener_target_s']} s), VAF {r['wiener_vaf_pct']:.2f} %",
            f"IRF Toeplitz/SVD+MDL: {r['irf_svd_mdl_s'] * 1e3:.1f} ms, error "
            f"{100 * r['irf_error_svd_rel']:.2f} %",
            f"IRF full-Toeplitz lstsq: {r['irf_full_toeplitz_lstsq_s'] * 1e3:.1f} ms, error "
            f"{100 * r['irf_error_lstsq_rel']:.2f} %",
            f"speed-up: {r['speedup_vs_lstsq']:.1f}x; condition number of the input "
            f"autocorrelation {r['input_autocorrelation_condition']:.2g} (a 200 Hz input at "
            "2 kHz leaves most lag directions unexcited: plain least squares amplifies noise)"]
