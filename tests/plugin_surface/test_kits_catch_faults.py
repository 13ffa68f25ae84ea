"""The conformance kits fail a faulty plugin and name the check it fails: throw-away plugins,
each with one fault, built on the plugin surface alone."""

from __future__ import annotations

from typing import Any

import pytest

from skinkit.plugin.conformance.effects import check_effect
from skinkit.plugin.conformance.optimisers import check_optimiser
from skinkit.plugin.conformance.trackers import check_tracker
from skinkit.plugin.effects import BaseEffect, Declared, declare, quantity
from skinkit.plugin.optimisers import OptimiseResult
from skinkit.plugin.trackers import TrackResult


class Bias(BaseEffect):
    """A sound lumped effect: a constant force bias along x (an instrument entry)."""

    name = "test-bias"
    kinds = ("lumped",)
    touches = {"lumped": frozenset({"instrument"})}

    def _declared(self) -> list[Declared]:
        return [declare("offset", 20.0, 0.0, "mN", -1000.0, 1000.0)]

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, [{"kind": "bias", "parameter": f"{self.name}.offset", "value": v["offset"],
                                     "channel": "tip_force", "component": 0, "basis": "constant"}])


class Mutating(Bias):
    def apply(self, model, p):  # noqa: ANN001, ANN201 - the fault under test
        out = super().apply(model, p)
        model["model"]["name"] = "changed"
        return out


class InexactNull(Bias):
    """Adds a second bias of 1 mN whatever its parameter (the model's parameter set holds the
    effect's own values, so only an edit beside them can spoil the null)."""

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        super()._apply_lumped(model, v)
        model["instrument"].append({"kind": "bias", "parameter": "zero-error", "value": 1e-3,
                                    "channel": "tip_force", "component": 0, "basis": "constant"})


class Undeclared(Bias):
    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        super()._apply_lumped(model, v)
        model["note"] = "an undeclared table"


class WrongEntry(Bias):
    def apply(self, model, p):  # noqa: ANN001, ANN201 - the fault under test
        from skinkit.errors import EffectError

        if model.get("model", {}).get("kind", "fe") != "lumped":
            raise EffectError("effects", "not a lumped model")
        return super().apply(model, p)


class StiffnessEdit(Bias):
    """Edits a value the model already has as a parameter: the parameter set overrides it, so
    the effect cannot move the prediction."""

    touches = {"lumped": frozenset({"lumped"})}
    once = False

    def _declared(self) -> list[Declared]:
        return [declare("ratio", 1.5, 1.0, "1", 0.2, 5.0)]

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        table = self.lumped(model)
        params = dict(table["parameters"])
        params["a"] = quantity(params["a"], "N", self.entry) * v["ratio"]
        table["parameters"] = params


class NullOutside(Bias):
    def null(self) -> dict[str, float]:
        return {"offset": 5.0}


class RegionNotInMetres(Bias):
    """Declares its force offset as a region's centre: the region scan needs lengths."""

    region = ("offset", "offset", "offset")


@pytest.mark.parametrize("plugin, failing", [
    (Mutating(), {"lumped: input unchanged", "lumped: tables"}),
    (InexactNull(), {"lumped: null"}),
    (Undeclared(), {"lumped: tables"}),
    (WrongEntry(), {"fe: refused"}),
    (StiffnessEdit(), {"lumped: sensitivity"}),
    (NullOutside(), {"parameters"}),
    (RegionNotInMetres(), {"parameters"}),
])
def test_the_effects_kit_names_the_fault(plugin, failing):
    report = check_effect(plugin)
    assert {c.name for c in report.failed} == failing, str(report)
    assert "FAIL" in str(report) and report.to_dict()["passed"] is False


def test_a_sound_uninstalled_effect_passes():
    report = check_effect(Bias())
    assert report.passed, str(report)
    assert {c.name for c in report.checks} >= {"lumped: null", "lumped: sensitivity", "fe: refused"}


class IgnoresBounds:
    name = "ignores-bounds"

    def minimise(self, fun, x0, lower, upper, jac=None, options=None):  # noqa: ANN001, ANN201
        from scipy.optimize import least_squares

        r = least_squares(fun, x0)
        return OptimiseResult(r.x, float(r.cost), int(r.nfev), bool(r.success), str(r.message))


def test_the_optimisers_kit_catches_an_ignored_bound():
    report = check_optimiser(IgnoresBounds())
    assert {c.name for c in report.failed} == {"active bound"}, str(report)


class Frozen:
    name = "frozen"

    def track(self, reference, current, points, subset_px=64, mask=None):  # noqa: ANN001, ANN201
        res = TrackResult.empty(len(points))
        res.valid[:] = True
        res.reason = [""] * len(points)
        res.displacement_px[:] = 0.0
        return res


def test_the_trackers_kit_catches_a_tracker_that_sees_no_motion():
    report = check_tracker(Frozen())
    assert {"shift", "edge", "bad input"} <= {c.name for c in report.failed}, str(report)


def test_the_effects_kit_checks_a_declared_elliptical_region():
    """``inclusion`` declares its elliptical form soundly; the same plugin pointing at a form it does
    not have, or at names that are not its ellipse's lengths and angle, is named a fault."""
    import copy

    from skinkit import registry
    from skinkit.plugin.conformance.effects import _ellipse_problems

    sound = registry.create("skinkit.effects", "inclusion")
    assert _ellipse_problems(sound) == []
    no_form = copy.copy(sound)
    no_form.region_ellipse = ("oval", ("x", "y", "a", "b", "angle"))
    assert "must be one of the effect's forms" in " ".join(_ellipse_problems(no_form))
    swapped = copy.copy(sound)
    swapped.region_ellipse = ("ellipse", ("x", "y", "a", "angle", "b"))
    got = " ".join(_ellipse_problems(swapped))
    assert "'angle' is not a declared parameter in m" in got
    assert "'b' is not a declared parameter in rad" in got
