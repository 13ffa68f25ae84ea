"""Shared fixtures. Tests that need the built-in plugins use the ``needs_plugins`` marker
(or ``pytest.importorskip("skinkit_plugins")``) so that the ``core`` tox environments,
which install skinkit alone, skip them with a reason."""

from __future__ import annotations

import importlib.util

import pytest

HAVE_PLUGINS = importlib.util.find_spec("skinkit_plugins") is not None
HAVE_HARDWARE = importlib.util.find_spec("skinkit_hardware") is not None


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    skip_plugins = pytest.mark.skip(reason="needs skinkit-plugins (not installed: core environment)")
    skip_hw = pytest.mark.skip(reason="needs skinkit-hardware (not installed: core environment)")
    # the suite never depends on machine load: a test of wall-clock behaviour runs only when
    # asked for by name (pytest -m realtime), on a machine known to be idle
    run_realtime = "realtime" in (config.getoption("markexpr", "") or "")
    skip_rt = pytest.mark.skip(reason="asserts wall-clock behaviour: run with -m realtime on an idle machine")
    # groups that share an expensive module fixture (xdist_group, run by one worker under
    # --dist loadgroup) go first, so that they run beside the rest instead of after it
    items.sort(key=lambda it: it.get_closest_marker("xdist_group") is None)
    for item in items:
        if "realtime" in item.keywords and not run_realtime:
            item.add_marker(skip_rt)
        if "needs_plugins" in item.keywords and not HAVE_PLUGINS:
            item.add_marker(skip_plugins)
        if "needs_hardware" in item.keywords and not HAVE_HARDWARE:
            item.add_marker(skip_hw)
