"""Reading a session for a model: the records it names, along the axis the model acts on, with
held-out protocols marked; and the comma-separated name lists the commands take."""

from __future__ import annotations

import os
from typing import Any


def split_names(text: str | None) -> list[str]:
    """``"a, b,c"`` -> ``["a", "b", "c"]``; None or empty -> ``[]``."""
    return [s.strip() for s in text.split(",") if s.strip()] if text else []


def read_session(model: Any, session: str | os.PathLike[str], holdout: str | None = None,
                 segments: str | None = None, axis: str | None = None, protocols: str | None = None,
                 noise: str = "auto") -> Any:
    """The observations of ``session`` for ``model``: only the records ``protocols`` names
    (comma-separated; default all, e.g. to leave out records another model describes),
    ``holdout`` (comma-separated protocols) marked held out, records split into ``segments``
    first, a one-axis CSV read along ``axis`` (default: the model's own axis when it is x, y or
    z, else z); ``noise``: how each record's noise is modelled (``"auto"``, ``"white"``, ``"ar"``:
    :func:`skinkit.forward.observations.channels_from_record`). Only the tip components the
    model reads (its ``record_components``, when it has them) need an estimable noise."""
    from skinkit.forward.observations import read_observations

    if axis is None:
        axis = str(getattr(model, "axis", "z"))
        axis = axis if axis in ("x", "y", "z") else "z"
    return read_observations(session, held_out=split_names(holdout), axis=axis, segments=segments,
                             protocols=split_names(protocols) or None, noise=noise,
                             components=getattr(model, "record_components", None))
