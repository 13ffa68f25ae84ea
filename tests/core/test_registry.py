"""The plugin registry: third-party distributions load like built-in ones; broken ones are
reported and do not stop the others."""

from __future__ import annotations

import json
import subprocess

import pytest

from skinkit import registry
from skinkit.errors import PluginError
from skinkit.interfaces import GROUPS, Law, missing_members, required_members

from .thirdparty import build_wheel, make_env, pip_install

GOOD_MODULE = '''
import numpy as np

class Drv:
    name = "tp-driver"
    def connect(self, **options): pass
    def home(self, contact_force_N=0.01): pass
    def run(self, protocol): return iter(())
    def emergency_stop(self): pass
    def disconnect(self): pass

class Trk:
    name = "tp-tracker"
    def track(self, reference, current, points, subset_px=64, mask=None): return None

class Prof:
    name = "tp-profiler"
    def profile(self, images, rig, frame=0): return None

class Lw:
    name = "tp-law"
    def parameters(self): return []
    def energy(self, C, p): return 0.5 * (np.trace(C, axis1=-2, axis2=-1) - 3)

class Opt:
    name = "tp-opt"
    def minimise(self, fun, x0, lower, upper, jac=None, options=None): return None

class Eff:
    name = "tp-effect"
    kinds = ("fe", "lumped")
    def parameters(self): return []
    def null(self): return {}
    def apply(self, model, p): return model
'''

GOOD_EPS = {
    "skinkit.drivers": {"tp-driver": "tp_good.plugins:Drv"},
    "skinkit.trackers": {"tp-tracker": "tp_good.plugins:Trk"},
    "skinkit.profilers": {"tp-profiler": "tp_good.plugins:Prof"},
    "skinkit.laws": {"tp-law": "tp_good.plugins:Lw"},
    "skinkit.optimisers": {"tp-opt": "tp_good.plugins:Opt"},
    "skinkit.effects": {"tp-effect": "tp_good.plugins:Eff"},
}


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    root = tmp_path_factory.mktemp("env")
    python = make_env(root / "venv")
    good = build_wheel(root, "tp-good", {"tp_good/__init__.py": "", "tp_good/plugins.py": GOOD_MODULE},
                       GOOD_EPS)
    bad = build_wheel(root, "tp-broken", {
        "tp_broken/__init__.py": "",
        "tp_broken/boom.py": "raise RuntimeError('tp-broken cannot find its calibration table')\n",
        "tp_broken/half.py": ("class HalfLaw:\n    name = 'half'\n"
                              "    def parameters(self):\n        return []\n"),
    }, {"skinkit.laws": {"tp-boom": "tp_broken.boom:Law", "tp-half": "tp_broken.half:HalfLaw"}})
    pip_install(python, good)
    pip_install(python, bad)
    return python


def _plugins_json(python) -> dict:
    out = subprocess.run([str(python), "-m", "skinkit", "plugins", "--json", "--check"],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def test_third_party_plugins_listed_ok_and_broken_reported(env):
    report = _plugins_json(env)
    assert set(report["groups"]) == set(GROUPS)
    for group, eps in GOOD_EPS.items():
        (name,) = eps
        entry = next(e for e in report["groups"][group] if e["name"] == name)
        assert entry["status"] == "ok", entry
        assert entry["dist"] == "tp-good" and entry["error"] is None
    laws = {e["name"]: e for e in report["groups"]["skinkit.laws"]}
    assert laws["tp-boom"]["status"] == "error" and laws["tp-boom"]["dist"] == "tp-broken"
    assert "tp-broken cannot find its calibration table" in laws["tp-boom"]["error"]
    assert "RuntimeError" in laws["tp-boom"]["error"]
    assert laws["tp-half"]["status"] == "error"
    assert "missing energy" in laws["tp-half"]["error"]
    assert laws["tp-law"]["status"] == "ok"  # the broken ones did not stop it


def test_third_party_law_usable_from_python(env):
    code = ("from skinkit import registry; import numpy as np; "
            "law = registry.create('skinkit.laws', 'tp-law'); "
            "print(float(law.energy(np.eye(3) * 2, {})))")
    out = subprocess.run([str(env), "-c", code], capture_output=True, text=True, check=True)
    assert float(out.stdout) == pytest.approx(1.5)


def test_unknown_plugin_and_group():
    with pytest.raises(PluginError, match="no plugin 'nope' in skinkit.laws"):
        registry.load("skinkit.laws", "nope")
    with pytest.raises(PluginError, match="unknown plugin group 'skinkit.toasters'"):
        registry.available("skinkit.toasters")


def test_protocol_members():
    assert required_members(Law) == ["energy", "name", "parameters"]

    class NoEnergy:
        name = "x"

        def parameters(self):
            return []

    assert missing_members(NoEnergy, Law) == ["energy"]

    class EnergyNotCallable(NoEnergy):
        energy = 3.0

    assert missing_members(EnergyNotCallable, Law) == ["energy (not callable)"]


def test_listing_is_lazy():
    """available() reads metadata only: nothing is imported."""
    import sys

    for group in GROUPS:
        for info in registry.available(group):
            module = info.value.split(":")[0]
            if module not in sys.modules:
                registry.available(group)
                assert module not in sys.modules


@pytest.mark.needs_plugins
def test_builtin_plugins_load():
    rep = registry.report(["skinkit.optimisers"])
    statuses = {s.info.name: s.status for s in rep["skinkit.optimisers"]}
    assert statuses.get("scipy-lsq") == "ok" and statuses.get("nlopt-bobyqa") == "ok"
