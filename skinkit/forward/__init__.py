"""Forward models: a model file plus a session -> predictions of every measured channel.

``load(MODEL)`` reads a model file (or a parsed description), applies its ``[[effects]]``
and returns a :class:`skinkit.interfaces.ForwardModel`: the finite-element model
(``[model] kind = "fe"``, the default; :mod:`skinkit.forward.fe`) or a lumped model
(``kind = "lumped"``; :mod:`skinkit.forward.lumped`). ``read_observations(SESSION)`` reads
what a session measured. A model may hold worker processes between predictions: close it
(``close()``, idempotent) or use it as a context manager. Then::

    obs = read_observations("session.h5")
    with load("docs/models/invivo_quick.toml") as model:
        pred = model.predict(model.parameters(), obs, sensitivities=True)
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from skinkit.errors import ForwardError
from skinkit.forward.observations import read_observations
from skinkit.interfaces import ForwardModel
from skinkit.schemas.regions import RegionProvider


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
         scheduler: Any = None, plugins: Mapping[str, Any] | None = None) -> ForwardModel:
    """The forward model of a model file or description, with its ``[[effects]]`` applied.
    Close it when done (``close()`` or ``with load(...) as model:``).

    ``workers``: worker processes for the protocols of a session (default: one per core;
    1: in this process); ``scheduler``: a Dask scheduler address (or cluster) instead;
    ``plugins``: effect name -> plugin object to use for ``[[effects]]`` of that name instead of
    the installed one (an effect under development). Raises :class:`ForwardError`,
    :class:`skinkit.errors.EffectError` or :class:`skinkit.fem.errors.ModelError` naming the
    entry at fault.
    """
    from skinkit.forward.effects import resolve

    if plugins:
        # the description check knows installed effects only: the given ones are checked by
        # resolve, against the plugin objects themselves
        spec = read_description(path_or_spec) if not isinstance(path_or_spec, Mapping) else dict(path_or_spec)
        tables = spec.get("effects")
        given = [t for t in tables or [] if isinstance(t, Mapping) and t.get("name") in plugins]
        spec = read_description({**spec, "effects": [t for t in tables or [] if t not in given]})
        spec["effects"] = tables
    else:
        spec = read_description(path_or_spec)
    kind = model_kind(spec)
    effects = resolve(spec.get("effects"), kind, plugins)
    if kind == "lumped":
        from skinkit.forward.lumped import build_lumped

        return build_lumped(spec, effects)
    from skinkit.forward.fe import FEForwardModel

    return FEForwardModel(spec, effects, workers=workers, scheduler=scheduler)


def region_partitions(spec: Mapping[str, Any]) -> RegionProvider | None:
    """The regions of the model's tracked surface that the gap diagnosis tests: a provider
    ``points (P, 2) [m] -> [RegionPartition, ...]`` (:mod:`skinkit.schemas.regions`) from a
    finite-element model's geometry (:func:`skinkit.fem.regions.region_partitions`); None for a
    lumped model, which predicts no surface."""
    if model_kind(spec) == "lumped":
        return None
    from skinkit.fem.regions import region_partitions as fe_regions

    return fe_regions(spec)


__all__ = ["ForwardModel", "load", "model_kind", "read_description", "read_observations", "region_partitions"]
