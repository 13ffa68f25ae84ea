"""The package imports downwards only: contract -> engines -> plugin surface -> applications ->
command line (``import_rings`` has the rings and the rules), and no two modules import each other
through any chain. Every import counts, those inside functions included."""

from __future__ import annotations

from pathlib import Path

from tests.core import import_rings as rings

PACKAGE = Path(__file__).resolve().parents[2] / "skinkit"


def test_every_import_goes_down_a_ring_and_none_forms_a_cycle():
    found = rings.violations(rings.module_sources(PACKAGE))
    assert not found, "\n".join(found)


def test_a_deliberate_upward_import_inside_a_function_is_caught():
    sources = rings.module_sources(PACKAGE)
    sources["skinkit.gap.diagnose"] += ("\n\ndef _sneaky():\n"
                                        "    from skinkit.cli import main\n    return main\n")
    found = rings.violations(sources)
    assert any(v.startswith("skinkit.gap.diagnose:") and "skinkit.cli (command line)" in v
               for v in found), found


def test_click_in_an_engine_is_caught():
    sources = rings.module_sources(PACKAGE)
    sources["skinkit.fem.solver"] = "import click\n" + sources["skinkit.fem.solver"]
    found = rings.violations(sources)
    assert any(v.startswith("skinkit.fem.solver:1 imports click") for v in found), found


def test_a_cycle_is_caught_even_within_a_ring():
    sources = {"skinkit": "", "skinkit.fem": "", "skinkit.fem.a": "from skinkit.fem import b\n",
               "skinkit.fem.b": "def f():\n    from skinkit.fem.a import g\n"}
    found = rings.violations(sources)
    assert found == ["import cycle: skinkit.fem.a -> skinkit.fem.b -> skinkit.fem.a"]


def test_a_type_only_import_is_not_a_cycle_but_still_may_not_go_up():
    sources = {"skinkit": "", "skinkit.fem": "", "skinkit.cli": "",
               "skinkit.fem.a": "from skinkit.fem import b\n",
               "skinkit.fem.b": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                "    from skinkit.fem.a import g\n    from skinkit.cli import h\n"}
    found = rings.violations(sources)
    assert found == ["skinkit.fem.b:4 imports skinkit.cli (command line) from the engines ring"]


def test_the_top_level_package_reaches_the_api_lazily_only():
    sources = rings.module_sources(PACKAGE)
    assert not [v for v in rings.violations(sources) if v.startswith("skinkit:")]
    # the same import at module level loads the engines on `import skinkit`: refused
    sources["skinkit"] = "from skinkit.api import fit\n" + sources["skinkit"]
    found = rings.violations(sources)
    assert any(v.startswith("skinkit:1 imports skinkit.api (applications)") for v in found), found
