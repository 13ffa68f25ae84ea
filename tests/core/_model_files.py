"""Small model files for the bad-input tests: a base spec (a tiny two-layer block, solved in
well under a second) and a TOML writer for the subset of TOML the model format uses."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any


def base_spec() -> dict[str, Any]:
    """A valid, fast model: a 2 x 2 block of two layers, indented 0.1 mm in 2 steps."""
    return copy.deepcopy({
        "model": {"name": "tiny"},
        "geometry": {"kind": "block", "size": ["10 mm", "10 mm"], "n": [2, 2],
                     "indenter_diameter": "6 mm"},
        "layers": [
            {"name": "top", "thickness": "1 mm", "elements": 1, "law": "neo-hookean-ni",
             "parameters": {"mu": "20 kPa", "K": "1 MPa"}},
            {"name": "base", "thickness": "4 mm", "elements": 1, "law": "neo-hookean-ni",
             "parameters": {"mu": "5 kPa", "K": "250 kPa"}},
        ],
        "boundary": {"fixed": ["bottom"]},
        "indenter": {"mode": "displacement", "components": [2]},
        "load": {"kind": "ramp", "value": ["0 mm", "0 mm", "-0.1 mm"], "steps": 2},
        "solver": {"rtol": 1e-8, "intorder": 4},
    })


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{json.dumps(str(k))} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {v!r} as TOML")


def to_toml(spec: dict[str, Any]) -> str:
    """TOML text of ``spec``: top-level tables, and ``layers`` as an array of tables."""
    out = []
    for key, val in spec.items():
        if isinstance(val, list) and val and all(isinstance(x, dict) for x in val):
            for item in val:
                out.append(f"[[{json.dumps(key)}]]")
                out += [f"{json.dumps(str(k))} = {_value(x)}" for k, x in item.items()]
        elif isinstance(val, dict):
            out.append(f"[{json.dumps(key)}]")
            out += [f"{json.dumps(str(k))} = {_value(x)}" for k, x in val.items()]
        else:
            out.insert(0, f"{json.dumps(key)} = {_value(val)}")
    return "\n".join(out) + "\n"


def write(spec: dict[str, Any], path: Path) -> Path:
    path.write_text(to_toml(spec), encoding="utf-8")
    return path
