"""Forward models: a model file plus a session -> predictions of every measured channel.

``load(MODEL)`` reads a model file (or a parsed description), applies its ``[[effects]]``
and returns a :class:`skinkit.interfaces.ForwardModel`: the finite-element model
(``[model] kind = "fe"``, the default; :mod:`skinkit.forward.fe`) or a lumped model
(``kind = "lumped"``; :mod:`skinkit.forward.lumped`). ``read_observations(SESSION)`` reads
what a session measured. Then::

    model = load("docs/models/invivo_quick.toml")
    obs = read_observations("session.h5")
    pred = model.predict(model.parameters(), obs, sensitivities=True)
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from skinkit.errors import ForwardError
from skinkit.forward.observations import read_observations


def read_description(path_or_spec: str | os.PathLike[str] | Mapping[str, Any]) -> dict[str, Any]:
    """A model description: the parsed TOML file, or a copy of the mapping given. Its session,
    surface, drive, instrument, fields, effects and bindings tables are checked here
    (:mod:`skinkit.forward.spec_check`): an error names the entry before any work."""
    from skinkit.forward.spec_check import check_description

    if isinstance(path_or_spec, Mapping):
        spec = dict(path_or_spec)
    else:
        from skinkit.fem.model import read_model

        spec = read_model(Path(path_or_spec))
    check_description(spec)
    return spec


def model_kind(spec: Mapping[str, Any]) -> str:
    """``"fe"`` or ``"lumped"`` from ``[model] kind`` (default ``"fe"``)."""
    kind = str(dict(spec.get("model", {}) or {}).get("kind", "fe"))
    if kind not in ("fe", "lumped"):
        raise ForwardError("model.kind", f"must be 'fe' or 'lumped', got {kind!r}")
    return kind


def load(path_or_spec: str | os.PathLike[str] | Mapping[str, Any], *, workers: int | None = None,
         scheduler: Any = None) -> Any:
    """The forward model of a model file or description, with its ``[[effects]]`` applied.

    ``workers``: worker processes for the protocols of a session (default: one per core;
    1: in this process); ``scheduler``: a Dask scheduler address (or cluster) instead.
    Raises :class:`ForwardError`, :class:`skinkit.errors.EffectError` or
    :class:`skinkit.fem.errors.ModelError` naming the entry at fault.
    """
    from skinkit.forward.effects import resolve

    spec = read_description(path_or_spec)
    kind = model_kind(spec)
    effects = resolve(spec.get("effects"), kind)
    if kind == "lumped":
        from skinkit.forward.lumped import build_lumped

        return build_lumped(spec, effects) if _takes_effects(build_lumped) else build_lumped(spec)
    from skinkit.forward.fe import FEForwardModel

    return FEForwardModel(spec, effects, workers=workers, scheduler=scheduler)


def _takes_effects(fn: Any) -> bool:
    import inspect

    try:
        return len(inspect.signature(fn).parameters) >= 2
    except (TypeError, ValueError):
        return False


__all__ = ["load", "model_kind", "read_description", "read_observations"]
