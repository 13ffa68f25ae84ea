"""The built-in plugins (``plugins/``) and the hardware layer (``hardware/``) use only the
declared plugin API: the contract modules and the plugin surface (``skinkit.plugin``: one module
per plugin kind and its conformance kit), each listed in ``docs/guide/writing-plugins.md``.
Checked on the source (ast), so a private import fails here before any third-party author
copies it."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

from skinkit.plugin import CONFORMANCE
from skinkit.plugin import KITS as PLUGIN_KITS

ROOT = Path(__file__).resolve().parents[2]

GUIDE = ROOT / "docs" / "guide" / "writing-plugins.md"

#: the contract a plugin may import from
CORE = ("skinkit", "skinkit.errors", "skinkit.units", "skinkit.schemas", "skinkit.registry",
        "skinkit.interfaces")
#: plugin kind -> its module (the stable API for that kind, with ``__all__``), and its
#: conformance kit; the package declares both
KITS = dict(PLUGIN_KITS)
DECLARED = (frozenset(CORE) | frozenset(KITS.values()) | frozenset(CONFORMANCE.values())
            | {"skinkit.plugin", "skinkit.plugin.conformance", "skinkit.plugin.conformance.report"})


def _source(module: str) -> Path | None:
    """The file of a skinkit module in this repository (found without importing it)."""
    base = ROOT.joinpath(*module.split("."))
    for p in (base.with_suffix(".py"), base / "__init__.py"):
        if p.is_file():
            return p
    return None


def _all_of(module: str) -> frozenset[str] | None:
    """The module's ``__all__`` (read from its source), None when it declares none."""
    path = _source(module)
    if path is None:
        return None
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__"
                                                for t in node.targets):
            return frozenset(ast.literal_eval(node.value))
    return None


def _is_skinkit(module: str | None) -> bool:
    return module is not None and (module == "skinkit" or module.startswith("skinkit."))


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _attribute_chain(node: ast.Attribute) -> tuple[str, list[str]] | None:
    """``(root name, [attr, ...])`` of ``root.a.b``; None when the root is not a plain name."""
    attrs = []
    cur: ast.expr = node
    while isinstance(cur, ast.Attribute):
        attrs.append(cur.attr)
        cur = cur.value
    return (cur.id, attrs[::-1]) if isinstance(cur, ast.Name) else None


def _check_imports(tree: ast.AST, where: str, declared: frozenset[str], bound: set[str]) -> list[str]:
    """Offending ``import``/``from`` statements anywhere in ``tree``; adds the names they bind
    to ``bound``."""
    out: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if not _is_skinkit(a.name):
                    continue
                bound.add(a.asname or a.name.split(".")[0])
                if a.name not in declared:
                    out.append(f"{where}:{node.lineno}: import {a.name} (not in the declared plugin API)")
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and _is_skinkit(node.module):
            mod = node.module
            exported = _all_of(mod) if mod in declared else None
            for a in node.names:
                bound.add(a.asname or a.name)
                if f"{mod}.{a.name}" in declared:  # from skinkit.fem import lawkit
                    continue
                if mod not in declared:
                    out.append(f"{where}:{node.lineno}: from {mod} import {a.name} "
                               f"({mod} is not in the declared plugin API)")
                elif _private(a.name):
                    out.append(f"{where}:{node.lineno}: from {mod} import {a.name} (private name)")
                elif a.name != "*" and exported is not None and a.name not in exported:
                    out.append(f"{where}:{node.lineno}: from {mod} import {a.name} "
                               f"(not in {mod}.__all__)")
    return out


def _check_attributes(tree: ast.AST, where: str, declared: frozenset[str], bound: set[str]) -> list[str]:
    """``x._name`` on a name bound by a skinkit import, and ``skinkit.a.b`` reaching an
    undeclared module after ``import skinkit...``."""
    out: list[str] = []
    inner = {id(n.value) for n in ast.walk(tree) if isinstance(n, ast.Attribute)}
    for node in ast.walk(tree):
        chain = _attribute_chain(node) if isinstance(node, ast.Attribute) else None
        if not chain or chain[0] not in bound:
            continue
        if _private(chain[1][-1]):
            out.append(f"{where}:{node.lineno}: {chain[0]}.{'.'.join(chain[1])} (private member)")
        if chain[0] == "skinkit" and id(node) not in inner:  # import skinkit; skinkit.fem.hyper.b2
            parts = ["skinkit", *chain[1]]
            mods = [m for m in (".".join(parts[:k]) for k in range(2, len(parts) + 1)) if _source(m)]
            if mods and mods[-1] not in declared:
                out.append(f"{where}:{node.lineno}: {'.'.join(parts)} ({mods[-1]} is not in the "
                           f"declared plugin API)")
    return out


def check_source(text: str, where: str, declared: frozenset[str] = DECLARED) -> list[str]:
    """``"<where>:<line>: <what>"`` for every use of skinkit outside ``declared``: an import of
    an undeclared module (module or function level, ``import`` or ``from``), an imported name
    that is private or not in the module's ``__all__``, an attribute ``x._name`` of a name
    bound by a skinkit import, and an undeclared module reached as ``skinkit.a.b``."""
    tree = ast.parse(text)
    bound: set[str] = set()  # names bound to skinkit modules or objects
    out = _check_imports(tree, where, declared, bound)
    out += _check_attributes(tree, where, declared, bound)
    return sorted(set(out), key=lambda s: (s.split(":")[0], int(s.split(":")[1]), s))


def check_tree(root: Path, base: Path = ROOT) -> list[str]:
    """:func:`check_source` over every ``.py`` file under ``root``, named relative to ``base``."""
    out: list[str] = []
    for path in sorted(root.rglob("*.py")):
        if "build" in path.parts:
            continue
        out += check_source(path.read_text(encoding="utf-8"), path.relative_to(base).as_posix())
    return out


@pytest.mark.parametrize("tree", ["plugins", "hardware"])
def test_plugins_and_hardware_use_only_the_declared_api(tree):
    found = check_tree(ROOT / tree)
    assert not found, "imports outside the declared plugin API:\n" + "\n".join(found)


_OFFENDER = '''\
import numpy as np
import skinkit.vision.subsets
from skinkit import registry
from skinkit.errors import SkinkitError
from skinkit.plugin import laws as lawkit
from skinkit.fem.hyper import b2
from skinkit.plugin.laws import _show, stress
from skinkit.plugin.laws import no_such_name
from skinkit_plugins.laws.goh import GOH
from . import sibling


def f(law, C, p):
    from skinkit.cli._types import FiniteFloat
    S = stress(law, C, p) + lawkit.tangent(law, C, p)
    return lawkit._energy_gradient(law, C, p), registry._cache, np._private, FiniteFloat, S


def g(C):
    import skinkit.plugin.laws
    return skinkit.fem.hyper.b2(C), skinkit.plugin.laws.b2(C)
'''


def test_the_checker_names_every_offence(tmp_path):
    # a throw-away plugin module with one offence of each kind, fed to the same checker
    (tmp_path / "offending_plugin").mkdir()
    (tmp_path / "offending_plugin" / "laws.py").write_text(_OFFENDER, encoding="utf-8")
    found = check_tree(tmp_path, base=tmp_path)
    assert all(s.startswith("offending_plugin/laws.py:") for s in found), found
    lines = [int(s.split(":")[1]) for s in found]
    # undeclared modules (2, 6, and 14 inside a function), a private name (7), a name the kit
    # does not export (8), private members of skinkit names (16: lawkit._energy_gradient and
    # registry._cache; np._private is not skinkit's), an undeclared module reached by
    # attribute (21: skinkit.fem.hyper, not skinkit.plugin.laws)
    assert lines == [2, 6, 7, 8, 14, 16, 16, 21], found
    assert "skinkit.fem.hyper is not in the declared plugin API" in found[1]
    assert "import _show (private name)" in found[2]
    assert "not in skinkit.plugin.laws.__all__" in found[3]
    assert "skinkit.cli._types is not in the declared plugin API" in found[4]
    assert {"lawkit._energy_gradient (private member)", "registry._cache (private member)"} == \
        {s.split(": ", 1)[1] for s in found[5:7]}
    assert found[7].endswith("skinkit.fem.hyper.b2 (skinkit.fem.hyper is not in the declared plugin API)")


def test_a_throwaway_private_import_in_a_fixture_tree_fails(tmp_path):
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "ok.py").write_text("from skinkit.plugin.laws import stress\n", encoding="utf-8")
    (tmp_path / "pkg" / "old.py").write_text("from skinkit.fem.lawkit import stress\n", encoding="utf-8")
    (tmp_path / "pkg" / "bad.py").write_text(
        "def g():\n    from skinkit.plugin.laws import _energy_gradient\n", encoding="utf-8")
    found = check_tree(tmp_path, base=tmp_path)
    assert found == ["pkg/bad.py:2: from skinkit.plugin.laws import _energy_gradient (private name)",
                     "pkg/old.py:1: from skinkit.fem.lawkit import stress "
                     "(skinkit.fem.lawkit is not in the declared plugin API)"]


@pytest.mark.parametrize("kit", sorted(set(KITS.values()) | set(CONFORMANCE.values())))
def test_every_kit_declares_its_api(kit):
    mod = importlib.import_module(kit)
    assert "stable API" in (mod.__doc__ or ""), f"{kit}: the docstring must say it is the stable API"
    names = _all_of(kit)
    assert names, f"{kit} has no __all__"
    missing = [n for n in names if not hasattr(mod, n)]
    assert not missing, f"{kit}.__all__ names what it does not define: {missing}"
    assert not [n for n in names if _private(n)]


def test_plugin_guide_lists_every_kit_and_name():
    guide = GUIDE.read_text(encoding="utf-8")
    for kit in set(KITS.values()):
        assert f"`{kit}`" in guide, f"{GUIDE.name} does not list {kit}"
        row = next((ln for ln in guide.splitlines() if ln.startswith("|") and f"`{kit}`" in ln), "")
        missing = [n for n in _all_of(kit) or () if f"`{n}`" not in row]
        assert not missing, f"{GUIDE.name}: the row of {kit} does not name {missing}"


def test_plugin_guide_lists_every_conformance_kit():
    guide = GUIDE.read_text(encoding="utf-8")
    for group, kit in CONFORMANCE.items():
        checks = sorted(n for n in _all_of(kit) or () if n.startswith("check_"))
        row = next((ln for ln in guide.splitlines() if ln.startswith("|") and f"`{kit}`" in ln), "")
        assert any(f"`{c}(" in row for c in checks), \
            f"{GUIDE.name}: no row for {kit} ({group}) naming one of {checks}"


def test_every_plugin_kind_has_a_module_and_the_engines_do_not_import_the_surface():
    from skinkit.interfaces import GROUPS

    assert set(GROUPS) <= set(KITS) and set(GROUPS) == set(CONFORMANCE)
    for path in sorted((ROOT / "skinkit").rglob("*.py")):
        rel = path.relative_to(ROOT / "skinkit").parts
        if rel[0] in ("plugin", "cli", "pipelines", "report", "bench", "__main__.py"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            mod = node.module if isinstance(node, ast.ImportFrom) else None
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else [mod or ""]
            assert not any(n == "skinkit.plugin" or n.startswith("skinkit.plugin.") for n in names), \
                f"{path.relative_to(ROOT)}:{node.lineno} imports the plugin surface from an engine"
