"""Code size: no module of skinkit over 800 lines and no function over 100, so that each file
keeps one job and each function reads as one algorithm."""

from __future__ import annotations

import ast
from pathlib import Path

#: most lines a module may have
MAX_FILE_LINES = 800
#: most lines a function (or method) may span, from its ``def`` line to its last line
MAX_FUNCTION_LINES = 100

PACKAGE = Path(__file__).resolve().parents[2] / "skinkit"


def _modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def _functions(tree: ast.AST) -> list[ast.FunctionDef | ast.AsyncFunctionDef]:
    return [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]


def test_the_package_is_found():
    assert len(_modules()) > 50, f"too few modules under {PACKAGE}: the walk looks in the wrong place"


def test_no_module_is_over_800_lines():
    long = []
    for path in _modules():
        n = len(path.read_text(encoding="utf-8").splitlines())
        if n > MAX_FILE_LINES:
            long.append(f"{path.relative_to(PACKAGE.parent)}: {n} lines")
    assert not long, f"modules over {MAX_FILE_LINES} lines (split them by job):\n" + "\n".join(long)


def test_no_function_is_over_100_lines():
    long = []
    for path in _modules():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for fn in _functions(tree):
            n = fn.end_lineno - fn.lineno + 1
            if n > MAX_FUNCTION_LINES:
                long.append(f"{path.relative_to(PACKAGE.parent)}:{fn.lineno} {fn.name}: {n} lines")
    assert not long, (f"functions over {MAX_FUNCTION_LINES} lines (split them into named steps):\n"
                      + "\n".join(long))
