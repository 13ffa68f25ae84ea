"""The rings of the package and a checker that walks every import of its source.

Rings, from the bottom: the contract (schemas, units, errors, registry, store, the interfaces and
the shipped model files) -> the engines (fem, vision, sysid, acquisition, forward, inverse, gap,
lab, export) -> the plugin surface (``skinkit.plugin``: the authors' kits re-export engine building
blocks, so it sits on the engines, and no engine imports it) -> the applications (pipelines,
report, bench) -> the command line. A module may import from its own ring or below, never above;
``click`` only in the command line. Every import counts — at module level, inside functions,
under ``TYPE_CHECKING`` — except that a module's import of its own package's ``__init__`` (which
Python runs first anyway) is not an edge, and the few upward imports of :data:`LAZY_EDGES`,
each allowed only inside a function (run on first use, never on import). A cycle between modules
is refused whatever the rings; for cycles, imports under ``TYPE_CHECKING`` (never executed) are
left out.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

#: ring of each top-level part of the package (its first name below ``skinkit``)
RINGS: dict[str, int] = {
    # contract
    "": 0, "errors": 0, "units": 0, "schemas": 0, "registry": 0, "store": 0, "interfaces": 0,
    "examples": 0, "jsonio": 0,
    # engines
    "fem": 1, "vision": 1, "sysid": 1, "acquisition": 1, "forward": 1, "inverse": 1, "gap": 1, "lab": 1,
    "export": 1,
    # the plugin surface
    "plugin": 2,
    # applications (``api``: the one-call Python API, skinkit.fit and skinkit.diagnose)
    "pipelines": 3, "report": 3, "bench": 3, "api": 3,
    # the command line
    "cli": 4, "__main__": 4,
}
#: modules placed apart from their package's ring: the command kit hands click types to command
#: authors, so it stands with the command line
MODULE_RINGS: dict[str, int] = {"skinkit.plugin.commands": 4}
#: upward imports allowed inside a function only: the top-level package's ``__getattr__`` hands
#: out ``skinkit.fit`` and ``skinkit.diagnose`` from the application-level API on first use, so
#: ``import skinkit`` loads no engine
LAZY_EDGES: frozenset[tuple[str, str]] = frozenset({("skinkit", "skinkit.api")})
RING_NAMES = {0: "contract", 1: "engines", 2: "plugin surface", 3: "applications", 4: "command line"}
#: third-party packages allowed only from a ring and up
THIRD_PARTY_FLOOR = {"click": 4}


@dataclass(frozen=True)
class Import:
    """One import statement's target, as found in ``module``'s source at ``line``."""

    module: str
    target: str
    line: int
    type_only: bool
    in_function: bool = False


def module_sources(root: Path) -> dict[str, str]:
    """Dotted module name -> source text of every ``.py`` file under ``root`` (the package)."""
    out = {}
    for p in sorted(root.rglob("*.py")):
        parts = list(p.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p.read_text(encoding="utf-8")
    return out


def _is_package(name: str, sources: Mapping[str, str]) -> bool:
    return any(m.startswith(name + ".") for m in sources)


def _type_checking_lines(tree: ast.AST) -> set[int]:
    lines: set[int] = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.If) and "TYPE_CHECKING" in ast.unparse(n.test):
            for sub in n.body:
                lines.update(range(sub.lineno, (sub.end_lineno or sub.lineno) + 1))
    return lines


def _function_lines(tree: ast.AST) -> set[int]:
    lines: set[int] = set()
    for n in ast.walk(tree):
        if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
            lines.update(range(n.lineno, (n.end_lineno or n.lineno) + 1))
    return lines


def imports(module: str, source: str, sources: Mapping[str, str]) -> list[Import]:
    """Every import in ``source`` (module ``module``), resolved to a module of ``sources`` where it
    is one (``from pkg import sub`` -> ``pkg.sub``) or kept as written (third-party)."""
    tree = ast.parse(source)
    typed = _type_checking_lines(tree)
    in_function = _function_lines(tree)
    package = module if _is_package(module, sources) else module.rpartition(".")[0]
    out = []
    for n in ast.walk(tree):
        if isinstance(n, ast.Import):
            targets = [a.name for a in n.names]
        elif isinstance(n, ast.ImportFrom):
            base = n.module or ""
            if n.level:
                up = package.split(".")[: len(package.split(".")) - (n.level - 1)]
                base = ".".join(up + ([n.module] if n.module else []))
            # a submodule imported by name is the dependency, not its package
            subs = [f"{base}.{a.name}" for a in n.names if f"{base}.{a.name}" in sources]
            targets = subs if len(subs) == len(n.names) else [base, *subs]
        else:
            continue
        for t in targets:
            while t and t not in sources and t.startswith("skinkit."):
                t = t.rpartition(".")[0]
            out.append(Import(module, t, n.lineno, n.lineno in typed, n.lineno in in_function))
    return out


def ring_of(module: str) -> int | None:
    """The ring of a skinkit module (None: not in the package) or a third-party floor."""
    if module == "skinkit":
        return 0
    for name, ring in MODULE_RINGS.items():
        if module == name or module.startswith(name + "."):
            return ring
    if module.startswith("skinkit."):
        return RINGS.get(module.split(".")[1])
    top = module.split(".")[0]
    return THIRD_PARTY_FLOOR.get(top)


def violations(sources: Mapping[str, str]) -> list[str]:
    """Every upward import, unranked module and module cycle in ``sources``, one line each."""
    out = []
    graph: dict[str, set[str]] = {m: set() for m in sources}
    for m, src in sources.items():
        own = ring_of(m)
        if own is None:
            out.append(f"{m}: not in any ring (add its package to RINGS)")
            continue
        for imp in imports(m, src, sources):
            if m.startswith(imp.target + ".") and imp.target in sources:
                continue  # its own package's __init__
            r = ring_of(imp.target)
            lazy = imp.in_function and (m, imp.target) in LAZY_EDGES
            if r is not None and r > own and not lazy:
                what = RING_NAMES.get(r, f"ring {r}") if imp.target.startswith("skinkit") else imp.target
                out.append(f"{m}:{imp.line} imports {imp.target} ({what}) from the "
                           f"{RING_NAMES[own]} ring")
            if imp.target in sources and imp.target != m and not imp.type_only:
                graph[m].add(imp.target)
    out.extend(f"import cycle: {' -> '.join(c)}" for c in cycles(graph))
    return out


def cycles(graph: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each closed into a
    loop for reading (``[a, b, a]``)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        # iterative deepening would be safer for huge graphs; a package's depth is small
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comp = sorted(comp)
                found.append([*comp, comp[0]])

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found
