"""The calibrated model as a model file: ``model.toml`` written by ``skinkit fit`` and ``skinkit gap
diagnose``.

The file is the input model description with the fitted values written in (SI numbers in place
of the file's entries), any effects a diagnosis added appended as ``[[effects]]`` tables at their
fitted values, and a ``[calibration]`` table recording where the values came from: the session,
the date (UTC), the skinkit version, the objective and, per fitted parameter, its value, unit,
standard error and 95 % interval (``low``, ``high`` = value ∓ 1.96 se, the Wald interval the fit
reports; absent when the standard error is undetermined). The loaders ignore ``[calibration]``:
the file is a model file like any other, and predicting a session with it reproduces the fit's
predictions (the values are written as shortest round-trip decimals, so they are read back
bit for bit). Comments of the input file are not kept.

A fitted parameter is written to the entry it is read from:

* ``<layer>.<law parameter>`` -> ``layers[i].parameters``; ``<layer>.prestretch.l1``, ``.l2``,
  ``.angle`` -> ``layers[i].prestress`` (``stretch``, ``angle``);
* ``<field>.<key>`` -> the ``[[fields]]`` table of that name;
* ``boundary.compliance`` -> ``boundary.compliance.value``;
* ``lumped.<name>`` -> ``[lumped.parameters]``, ``lumped.g<k>``/``tau<k>`` -> the k-th
  ``[[lumped.relaxation]]``, ``lumped.softening``/``cycles`` -> ``[lumped.preconditioning]``;
* an ``[[instrument]]`` entry's ``parameter``, ``azimuth_parameter``, ``tau_parameter`` -> its
  ``value``, ``azimuth``, ``tau``;
* ``<effect>.<key>`` -> the ``[[effects]]`` table of that name (or ``instance`` label).

Every written file is loaded again before it is kept and each parameter's value compared with
the fitted one: a parameter that did not land is an error naming it, never a silent wrong model.
"""

from __future__ import annotations

import copy
import datetime as _dt
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from skinkit.errors import SkinkitError

#: the file name written into an output directory
MODEL_FILE = "model.toml"
#: the top-level table of the metadata (ignored by the model loaders)
CALIBRATION_TABLE = "calibration"
#: the 95 % interval's half-width in standard errors (1.96, as the fit's summary and the gap report)
Z95 = 1.96


def calibrated_description(spec: Mapping[str, Any], values: Mapping[str, float],
                           effects: Sequence[Mapping[str, Any]] = ()) -> dict[str, Any]:
    """A copy of the model description ``spec`` (as parsed from its file, effects not applied)
    with the ``effects`` tables appended and ``values`` (parameter name -> SI value) written into
    their entries (module docstring). Names without an entry are left out silently here;
    :func:`write_calibrated` checks that every value landed."""
    out = copy.deepcopy(dict(spec))
    out.pop(CALIBRATION_TABLE, None)   # a calibrated model calibrated again: the new record only
    if effects:
        out["effects"] = list(out.get("effects") or []) + [dict(t) for t in effects]
    for name, v in values.items():
        _place(out, str(name), float(v))
    return out


def _place(spec: dict[str, Any], name: str, v: float) -> bool:
    """Write ``v`` into the entry of parameter ``name``; False when no entry holds it."""
    for writer in (_effect, _instrument, _lumped, _compliance, _layer, _field):
        if writer(spec, name, v):
            return True
    return False


def _effect(spec: dict[str, Any], name: str, v: float) -> bool:
    head, _, local = name.partition(".")
    for t in spec.get("effects") or []:
        if isinstance(t, dict) and str(t.get("instance", t.get("name"))) == head and local:
            t[local] = v
            return True
    return False


def _instrument(spec: dict[str, Any], name: str, v: float) -> bool:
    for e in spec.get("instrument") or []:
        for key, target in (("parameter", "value"), ("azimuth_parameter", "azimuth"),
                            ("tau_parameter", "tau")):
            if isinstance(e, dict) and e.get(key) == name:
                e[target] = v
                return True
    return False


def _lumped(spec: dict[str, Any], name: str, v: float) -> bool:
    lt = spec.get("lumped")
    if not name.startswith("lumped.") or not isinstance(lt, dict):
        return False
    local = name.removeprefix("lumped.")
    pars = lt.get("parameters")
    if isinstance(pars, dict) and local in pars:
        pars[local] = v
        return True
    m = re.fullmatch(r"(g|tau)(\d+)", local)
    rel = lt.get("relaxation") or []
    if m and 1 <= int(m.group(2)) <= len(rel):
        rel[int(m.group(2)) - 1][m.group(1)] = v
        return True
    pre = lt.get("preconditioning")
    if isinstance(pre, dict) and local in ("softening", "cycles"):
        pre[local] = v
        return True
    return False


def _compliance(spec: dict[str, Any], name: str, v: float) -> bool:
    c = dict(spec.get("boundary") or {}).get("compliance")
    if name != "boundary.compliance" or not isinstance(c, dict):
        return False
    c["value"] = v
    return True


def _layer(spec: dict[str, Any], name: str, v: float) -> bool:
    region, _, local = name.partition(".")
    layer = next((L for L in spec.get("layers") or [] if isinstance(L, dict) and L.get("name") == region),
                 None)
    if layer is None or not local:
        return False
    if local.startswith("prestretch."):
        pre = layer.setdefault("prestress", {})
        if local == "prestretch.angle":
            pre["angle"] = v
        else:   # prestretch.l1, .l2: the in-plane stretches
            st = [float(x) for x in pre.get("stretch", [1.0, 1.0])]
            st[int(local[-1]) - 1] = v
            pre["stretch"] = st
        return True
    layer.setdefault("parameters", {})[local] = v
    return True


def _field(spec: dict[str, Any], name: str, v: float) -> bool:
    head, _, key = name.partition(".")
    for f in spec.get("fields") or []:
        if isinstance(f, dict) and f.get("name") == head and key:
            f[key] = v
            return True
    return False


def calibration_record(values: Mapping[str, float], units: Mapping[str, str],
                       se: Mapping[str, float | None], *, session: str | os.PathLike[str], objective: str,
                       command: str, model_file: str | os.PathLike[str] | None = None,
                       notes: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The ``[calibration]`` table: ``session`` (absolute path), ``model_file`` (the input),
    ``command``, ``date`` (UTC, ISO 8601), ``skinkit_version``, ``objective``, the ``notes`` (TOML
    values: χ²/ν, converged, added effects...) and ``parameters``: per fitted parameter ``value``
    and ``unit`` (SI), ``se`` and the 95 % interval ``low``/``high`` [unit] where the standard error
    is a finite number, else ``interval = "undetermined"``."""
    from skinkit import __version__

    pars: dict[str, dict[str, Any]] = {}
    for n, v in values.items():
        p: dict[str, Any] = {"value": float(v), "unit": str(units.get(n, "1"))}
        s = se.get(n)
        if s is not None and math.isfinite(float(s)):
            p.update(se=float(s), low=float(v) - Z95 * float(s), high=float(v) + Z95 * float(s))
        else:
            p["interval"] = "undetermined"
        pars[str(n)] = p
    rec: dict[str, Any] = {"command": command, "session": str(Path(session).resolve()),
                           "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                           "skinkit_version": __version__, "objective": objective}
    if model_file is not None:
        rec["model_file"] = str(Path(model_file).resolve())
    rec.update({k: v for k, v in (notes or {}).items() if v is not None})
    rec["parameters"] = pars
    return rec


def write_calibrated(out_dir: str | os.PathLike[str], spec: Mapping[str, Any], values: Mapping[str, float],
                     se: Mapping[str, float | None], *, session: str | os.PathLike[str], objective: str,
                     command: str, effects: Sequence[Mapping[str, Any]] = (),
                     model_file: str | os.PathLike[str] | None = None,
                     notes: Mapping[str, Any] | None = None,
                     loader: Callable[[Mapping[str, Any]], Any] | None = None) -> Path:
    """Write ``out_dir/model.toml``: :func:`calibrated_description` of ``spec`` with ``values``
    (fitted parameter -> SI value) and ``effects``, plus :func:`calibration_record` (``se``:
    standard errors [SI], None where undetermined). The description is loaded first
    (``loader``, default :func:`skinkit.forward.load` with one worker) and every parameter's value
    compared with ``values``: a mismatch raises :class:`SkinkitError` naming the parameters. The
    file is written to a temporary name and renamed. Returns its path."""
    import tomli_w

    desc = calibrated_description(spec, values, effects)
    units = _check_landed(desc, values, loader)
    desc[CALIBRATION_TABLE] = calibration_record(values, units, se, session=session, objective=objective,
                                                 command=command, model_file=model_file, notes=notes)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / MODEL_FILE
    tmp = path.with_name(path.name + ".part")
    head = (f"# The calibrated model written by `{command}`: the input model file with the fitted\n"
            "# values (SI) written in; [calibration] records the session and the 95 % intervals.\n\n")
    try:
        tmp.write_text(head + tomli_w.dumps(_plain(desc)), encoding="utf-8")
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise SkinkitError(f"{path}: cannot write the calibrated model ({exc.strerror or exc})") from None
    return path


def _check_landed(desc: Mapping[str, Any], values: Mapping[str, float],
                  loader: Callable[[Mapping[str, Any]], Any] | None) -> dict[str, str]:
    """Load ``desc`` and compare its parameters with ``values``; their units (name -> SI unit)."""
    if loader is None:
        from skinkit.forward import load

        def loader(s: Mapping[str, Any]) -> Any:
            return load(s, workers=1)
    model = loader(desc)
    try:
        ps = model.parameters()
    finally:
        model.close()
    missed = [n for n, v in values.items()
              if n not in ps.names or not math.isclose(float(ps[n]), float(v), rel_tol=1e-14, abs_tol=1e-300)]
    if missed:
        raise SkinkitError("the calibrated model file could not hold the fitted value of "
                           f"{', '.join(missed)} (no entry of the model file is read as that parameter); "
                           "no model.toml written")
    return {n: ps.param(n).unit for n in values}


def _plain(x: Any) -> Any:
    """``x`` with numpy scalars as Python numbers and tuples as lists (what TOML writes)."""
    if isinstance(x, Mapping):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if hasattr(x, "item") and callable(x.item):
        return x.item()
    return x


__all__ = ["CALIBRATION_TABLE", "MODEL_FILE", "Z95", "calibrated_description", "calibration_record",
           "write_calibrated"]
