"""What a diagnosis checks before it runs: the candidate effects and the session's channels.

Every refusal is a :class:`GapError` naming the option or the protocol that is wrong.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from skinkit.errors import SkinkitError
from skinkit.schemas import Observations


class GapError(SkinkitError):
    """A diagnosis that cannot run: no free parameter, an unknown or inapplicable effect, a
    session without the channels the model predicts."""


def check_effects(kind: str, present: Sequence[str], effects: Sequence[str] | None) -> list[str]:
    """The candidate effects: ``effects`` checked (installed, applicable to ``kind``, not already
    in the model), or every applicable installed effect the model does not have."""
    from skinkit import registry
    from skinkit.forward.visibility import applicable_effects

    ok = applicable_effects(kind)
    if effects is None:
        return [e for e in ok if e not in present]
    installed = registry.names("skinkit.effects")
    out = []
    for e in effects:
        if e not in installed:
            raise GapError(f"--effects {e!r}: no such effect is installed "
                           f"(installed: {', '.join(installed)})")
        if e not in ok:
            raise GapError(f"--effects {e!r}: does not apply to a {kind!r} model "
                           f"(effects for {kind} models: {', '.join(ok)})")
        if e in present:
            raise GapError(f"--effects {e!r}: the model already has this effect")
        if e not in out:
            out.append(e)
    if not out:
        raise GapError("--effects: no effect named")
    return out


def check_channels(model: Any, observations: Observations) -> None:
    """Every protocol must hold the channel that drives the model and one it predicts (a lumped
    model predicts the other tip channel; a finite-element one also the tracked points)."""
    from skinkit.inverse.design import _model_drive

    drive = _model_drive(model)
    if drive is None:
        return
    other = "tip_force" if drive == "tip_position" else "tip_position"
    predicted = {other} if getattr(model, "kind", "fe") == "lumped" else {other, "points", "points_2d"}
    for po in observations:
        if drive not in po.channels:
            raise GapError(f"session protocol {po.name!r} has no {drive!r} channel to drive the model "
                           f"(it has {sorted(po.channels)})")
        if not predicted & set(po.channels):
            raise GapError(f"session protocol {po.name!r} has no channel the model predicts "
                           f"({', '.join(sorted(predicted))}; it has {sorted(po.channels)})")


__all__ = ["GapError", "check_effects", "check_channels"]
