"""What a person sees of a result or a session in Python: a short text (``repr``), a small HTML
table (a notebook's ``_repr_html_``) and a pandas table (``to_dataframe``).

The texts are at most :data:`MAX_LINES` lines and never print an array: a session's samples or a
fit's covariance are summarised by their counts and shapes; the numbers themselves are in the
objects' attributes and in :meth:`to_dict`. pandas is optional (``pip install skinkit[table]``):
only ``to_dataframe`` needs it. Gap reports have their own module, :mod:`skinkit.schemas.display_gap`.

Objects are read by their attributes (duck typing), so this module imports none of the classes
it shows and the schema modules may import it lazily without a cycle.
"""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Sequence
from typing import Any

from skinkit.units import unit_suffix

#: most lines a ``repr`` prints
MAX_LINES = 15
#: most rows of a listing (parameters, protocols, candidates) before "... N more"
MAX_ROWS = 8
#: what the missing optional dependency is installed with
PANDAS_HINT = "pip install skinkit[table]"


# -- shared helpers ---------------------------------------------------------------------------
def num(value: Any, spec: str = ".4g") -> str:
    """``value`` formatted with ``spec``; ``"—"`` for None, ``"nan"``/``"inf"`` as such."""
    if value is None:
        return "—"
    try:
        x = float(value)
    except (TypeError, ValueError):
        return str(value)
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:{spec}}"


def percent(fraction: Any) -> str:
    """A fraction as ``"95 %"``; ``"—"`` for None."""
    return "—" if fraction is None else f"{100 * float(fraction):.0f} %"


def require_pandas() -> Any:
    """The pandas module; an :class:`ImportError` naming the extra that installs it."""
    try:
        import pandas
    except ImportError:
        raise ImportError(f"to_dataframe() needs pandas, an optional dependency of skinkit: "
                          f"{PANDAS_HINT}") from None
    return pandas


def table(rows: Sequence[Sequence[Any]], header: Sequence[str] | None = None,
          indent: str = "  ") -> list[str]:
    """Rows of text cells in left-aligned columns (numbers right-aligned), one string per row."""
    body = [[str(c) for c in r] for r in rows]
    cells = ([[str(h) for h in header]] if header else []) + body
    if not cells:
        return []
    n = max(len(r) for r in cells)
    widths = [max(len(r[j]) for r in cells if j < len(r)) for j in range(n)]

    def numeric(c: str) -> bool:
        return c[:1] in "-+0123456789" or c in ("—", "nan", "inf")

    # a column of numbers (its header too) is right-aligned; the first column never is
    right = [j > 0 and bool(body) and all(numeric(r[j]) for r in body if j < len(r)) for j in range(n)]
    return [(indent + "  ".join(c.rjust(widths[j]) if right[j] else c.ljust(widths[j])
                                for j, c in enumerate(r))).rstrip() for r in cells]


def more(n_shown: int, n_total: int, where: str) -> list[str]:
    """``["  ... and N more (where)"]`` when rows were left out, else ``[]``."""
    return [f"  ... and {n_total - n_shown} more ({where})"] if n_total > n_shown else []


def html_table(caption: str, header: Sequence[str], rows: Iterable[Sequence[Any]],
               notes: Sequence[str] = ()) -> str:
    """A small HTML table: ``caption`` above, ``notes`` (one line each) below; every text escaped."""
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    foot = "".join(f"<div>{html.escape(n)}</div>" for n in notes)
    return (f"<div class=\"skinkit\"><table><caption style=\"text-align:left\"><b>{html.escape(caption)}"
            f"</b></caption><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>{foot}</div>")


def frame(records: list[dict[str, Any]], columns: Sequence[str]) -> Any:
    """A pandas DataFrame of ``records`` with exactly ``columns`` (empty records: no rows)."""
    pd = require_pandas()
    return pd.DataFrame.from_records(records, columns=list(columns))


# -- fit result -------------------------------------------------------------------------------
#: the columns of :meth:`FitResult.to_dataframe`
FIT_COLUMNS = ("parameter", "value", "se", "unit", "free", "lower", "upper", "identifiable")


def _identifiable(result: Any) -> dict[str, bool]:
    flags = (result.identifiability or {}).get("identifiable")
    return {str(k): bool(v) for k, v in flags.items()} if isinstance(flags, dict) else {}


def fit_records(result: Any) -> list[dict[str, Any]]:
    """One record per parameter of a fit (fixed ones included): ``parameter``, ``value`` [SI],
    ``se`` [SI] (None when not free or not computed), ``unit``, ``free``, ``lower``, ``upper``
    [SI], ``identifiable`` (None when not free or not analysed)."""
    ident = _identifiable(result)
    out = []
    for p in result.parameters:
        se = result.se.get(p.name) if p.free else None
        out.append({"parameter": p.name, "value": p.value, "se": None if se is None else float(se),
                    "unit": p.unit, "free": p.free, "lower": p.lower, "upper": p.upper,
                    "identifiable": ident.get(p.name) if p.free else None})
    return out


def _fit_summary(result: Any) -> str:
    n_obs = result.extra.get("n_observations")
    parts = [f"objective {num(result.objective)}"]
    if result.chi2_per_dof is not None:
        parts.append(f"χ²/ν {num(result.chi2_per_dof)}")
    if n_obs is not None:
        parts.append(f"{n_obs} samples")
    if result.aic is not None:
        parts.append(f"AIC {num(result.aic, '.1f')}")
    return ", ".join(parts)


def fit_lines(result: Any) -> list[str]:
    """The text of ``repr(FitResult)``: the model, whether it converged, each free parameter's
    value ± standard error with its unit, the objective and the counts (at most :data:`MAX_LINES`)."""
    state = "converged" if result.converged else f"not converged ({result.message})"
    lines = [f"FitResult {result.model}: {state}, {result.n_evaluations} evaluations, "
             f"{num(result.wall_s, '.2f')} s"]
    recs = [r for r in fit_records(result) if r["free"]]
    rows = [[r["parameter"], "=", num(r["value"]), "±", num(r["se"]), unit_suffix(r["unit"]).strip(),
             "" if r["identifiable"] is not False else "(not identifiable)"] for r in recs[:MAX_ROWS]]
    lines += table(rows)
    lines += more(len(rows), len(recs), "to_dataframe() lists them all")
    fixed = len(result.parameters) - len(recs)
    if fixed:
        lines.append(f"  + {fixed} fixed parameter(s)")
    lines.append("  " + _fit_summary(result))
    if result.held_out:
        held = ", ".join(f"{k} {num(v)}" for k, v in list(result.held_out.items())[:4])
        lines.append(f"  held out (RMS weighted residual): {held}")
    return lines[:MAX_LINES]


def fit_html(result: Any) -> str:
    """The notebook view of a fit: a table of its parameters, the objective below."""
    state = "converged" if result.converged else "not converged"
    rows = [[r["parameter"], num(r["value"]), num(r["se"]), unit_suffix(r["unit"]).strip(),
             "free" if r["free"] else "fixed"] for r in fit_records(result)]
    notes = [_fit_summary(result), f"{result.n_evaluations} evaluations, {num(result.wall_s, '.2f')} s"]
    return html_table(f"FitResult {result.model} ({state})", ["parameter", "value", "± se", "unit", ""],
                      rows, notes)


def fit_frame(result: Any) -> Any:
    """The parameters of a fit as a DataFrame, columns :data:`FIT_COLUMNS` (values in SI)."""
    return frame(fit_records(result), FIT_COLUMNS)


# -- sessions and predictions -----------------------------------------------------------------
def _shape(a: Any) -> str:
    return "×".join(str(n) for n in getattr(a, "shape", ()))


def channel_text(ch: Any) -> str:
    """One channel in a few words: name, shape, unit, noise level per component."""
    noise = ", ".join(num(s, ".3g") for s in ch.noise)
    return f"{ch.name} ({_shape(ch.values)}, σ {noise}{unit_suffix(ch.unit)})"


def channel_lines(ch: Any) -> list[str]:
    """The text of ``repr(Channel)``."""
    t = ch.time_s
    span = f"{num(t[0], '.4g')} to {num(t[-1], '.4g')} s" if t.size else "no samples"
    return [f"Channel {ch.name} [{ch.unit}]: values {_shape(ch.values)}, {ch.n_valid} valid entries, {span}",
            f"  noise σ per component: {', '.join(num(s, '.3g') for s in ch.noise)}{unit_suffix(ch.unit)} "
            f"({ch.noise_source})"]


def protocol_line(p: Any) -> str:
    """One protocol of a session on one line: name, kind, duration, held out, its channels."""
    held = ", held out" if p.held_out else ""
    chans = "; ".join(channel_text(c) for c in p.channels.values()) or "no channel"
    return f"{p.name} ({p.protocol.kind}, {num(p.duration_s, '.4g')} s{held}): {chans}"


def observations_lines(obs: Any) -> list[str]:
    """The text of ``repr(Observations)``: the source, one line per protocol (at most
    :data:`MAX_ROWS`), the profile's size."""
    n_held = sum(1 for p in obs if p.held_out)
    profile = "" if obs.profile is None else f", profile of {obs.profile.n_points} points"
    lines = [f"Observations from {obs.source or '(no file)'}: {len(obs)} protocol(s), "
             f"{n_held} held out{profile}"]
    ps = list(obs)
    lines += ["  " + protocol_line(p) for p in ps[:MAX_ROWS]]
    lines += more(min(len(ps), MAX_ROWS), len(ps), ".names lists them")
    return lines


def prediction_lines(pred: Any) -> list[str]:
    """The text of ``repr(Prediction)``: per protocol the channels predicted and their shapes,
    the parameters with derivatives and how they were obtained."""
    methods = sorted(set(pred.methods.values()))
    derivs = (f", derivatives of {len(pred.methods)} parameter(s) ({', '.join(methods)})"
              if pred.methods else "")
    lines = [f"Prediction: {len(pred.protocols)} protocol(s){derivs}"]
    items = list(pred.protocols.items())
    for p, chans in items[:MAX_ROWS]:
        driven = f" (driven by {pred.inputs[p]})" if p in pred.inputs else ""
        lines.append(f"  {p}: " + ", ".join(f"{c} {_shape(cp.values)}" for c, cp in chans.items()) + driven)
    lines += more(min(len(items), MAX_ROWS), len(items), ".protocols holds them")
    return lines


def channel_prediction_line(cp: Any) -> str:
    """The text of ``repr(ChannelPrediction)``."""
    d = f", derivatives of {', '.join(list(cp.d)[:6])}{' ...' if len(cp.d) > 6 else ''}" if cp.d else ""
    part = "" if cp.predicted is None else f", {int(cp.predicted.sum())} entries predicted"
    return f"ChannelPrediction: values {_shape(cp.values)}{part}{d}"


__all__ = ["FIT_COLUMNS", "MAX_LINES", "PANDAS_HINT", "channel_lines", "channel_prediction_line",
           "fit_frame", "fit_html", "fit_lines", "fit_records", "html_table", "num", "observations_lines",
           "prediction_lines", "protocol_line", "require_pandas"]
