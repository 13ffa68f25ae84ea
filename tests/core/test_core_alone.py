"""The core with no plugin distribution installed (the tox ``core`` environments).

In a ``full`` environment these tests skip: there the plugins are installed on purpose.
"""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from skinkit import registry
from skinkit.cli import cli
from skinkit.errors import PluginError
from skinkit.interfaces import GROUPS

from ..conftest import HAVE_HARDWARE, HAVE_PLUGINS

pytestmark = pytest.mark.skipif(HAVE_PLUGINS or HAVE_HARDWARE,
                                reason="plugin distributions installed; run in a core environment "
                                       "(tox -e py311-core) to check the core alone")


def test_plugins_lists_six_empty_groups():
    res = CliRunner().invoke(cli, ["plugins", "--json"])
    assert res.exit_code == 0
    groups = json.loads(res.stdout)["groups"]
    assert set(groups) == set(GROUPS)
    assert all(not [e for e in v if e["dist"] in ("skinkit-plugins", "skinkit-hardware")]
               for v in groups.values())


def test_loading_a_builtin_plugin_says_it_is_not_installed():
    with pytest.raises(PluginError, match="no plugin 'scipy-lsq' in skinkit.optimisers"):
        registry.load("skinkit.optimisers", "scipy-lsq")


def test_demo_names_the_plugins_it_needs(tmp_path):
    res = CliRunner().invoke(cli, ["demo", "--out", str(tmp_path / "d")])
    assert res.exit_code == 2 and "skinkit-plugins" in res.output and "skinkit.laws:goh" in res.output
    assert not (tmp_path / "d").exists()
