"""Every installed plugin passes the conformance kit of its kind: a plugin installed next to
skinkit is checked exactly like the built-in ones, with no test naming it."""

from __future__ import annotations

import pytest

from skinkit import registry
from skinkit.plugin.conformance.drivers import check_driver
from skinkit.plugin.conformance.effects import check_effect
from skinkit.plugin.conformance.laws import check_law
from skinkit.plugin.conformance.profilers import check_profiler
from skinkit.plugin.conformance.trackers import check_tracker


@pytest.mark.parametrize("name", registry.names("skinkit.effects"))
def test_every_effect_conforms(name):
    # lumped checks for every effect that applies to lumped models; the finite-element ones
    # (coarsest mesh, a few seconds) for the effects of finite-element models alone
    report = check_effect(name)
    assert report.passed, str(report)


@pytest.mark.parametrize("name", registry.names("skinkit.laws"))
def test_every_law_conforms(name):
    report = check_law(registry.create("skinkit.laws", name))
    assert report.passed, str(report)


@pytest.mark.parametrize("name", registry.names("skinkit.trackers"))
def test_every_tracker_conforms(name):
    report = check_tracker(name)
    assert report.passed, str(report)


@pytest.mark.parametrize("name", registry.names("skinkit.profilers"))
def test_every_profiler_conforms(name):
    report = check_profiler(name)
    assert report.passed, str(report)


@pytest.mark.parametrize("name", registry.names("skinkit.drivers"))
def test_every_driver_conforms(name):
    report = check_driver(name)
    assert report.passed, str(report)
