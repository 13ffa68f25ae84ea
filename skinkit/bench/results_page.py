"""A Markdown results page written by the benchmark that measured it.

At its top: the exact command line, the skinkit version, the machine (platform, CPU, cores,
memory, Python, NumPy and SciPy versions) and the UTC date; then the figures (text lines and
tables) and the whole result as JSON. ``docs/results/`` pages are written this way, so that no
measured figure is typed by hand.
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from skinkit import __version__, jsonio

#: a table: column titles, then rows of cells (text)
Table = tuple[Sequence[str], Sequence[Sequence[str]]]


def _cpu_model() -> str:
    """The CPU's model name where the system says it (Linux), else what platform knows."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def _memory_gb() -> float | None:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1e9
    except (AttributeError, OSError, ValueError):  # not every system has these
        return None


def _version(module: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(module)
    except PackageNotFoundError:
        return "not installed"


def machine() -> dict[str, Any]:
    """What the figures were measured on: platform, CPU model, cores, memory [GB], Python,
    NumPy and SciPy versions, and the 1-minute load average where the system has one."""
    mem = _memory_gb()
    return {"platform": platform.platform(), "cpu": _cpu_model(), "cpu_count": os.cpu_count(),
            "memory_gb": None if mem is None else round(mem, 1), "python": platform.python_version(),
            "numpy": _version("numpy"), "scipy": _version("scipy"),
            "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None}


def _md_cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _table(cols: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    out = ["| " + " | ".join(_md_cell(c) for c in cols) + " |", "|" + "---|" * len(cols)]
    out += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in rows]
    return out


def render(title: str, command: str, result: Any, lines: Sequence[str] = (),
           tables: Sequence[Table] = (), when: _dt.datetime | None = None,
           host: dict[str, Any] | None = None) -> str:
    """The page as Markdown.

    Args:
        title: the page's heading.
        command: the exact command line that measured the figures.
        result: the benchmark's JSON-ready result (written in full at the end).
        lines: the figures as text lines (what the command prints).
        tables: figures as tables (column titles, rows of cells).
        when: the UTC date of the measurement (default now).
        host: :func:`machine`'s description (default this machine).
    """
    when = when or _dt.datetime.now(_dt.timezone.utc)
    m = host if host is not None else machine()
    mem = "unknown" if m.get("memory_gb") is None else f"{m['memory_gb']:g} GB"
    load = m.get("load_average_1min")
    out = [f"# {title}", "",
           f"Written by `{command}` (skinkit {__version__}) on {when:%Y-%m-%d %H:%M} UTC.", "",
           f"Machine: {m['platform']}; {m['cpu']}, {m['cpu_count']} cores, {mem} memory; Python "
           f"{m['python']}, NumPy {m['numpy']}, SciPy {m['scipy']}"
           + ("" if load is None else f"; load average {load:.1f} when written") + ".", ""]
    if lines:
        out += ["```text", *lines, "```", ""]
    for cols, rows in tables:
        out += [*_table(cols, rows), ""]
    out += ["<details><summary>All figures (JSON)</summary>", "", "```json", jsonio.dumps(result, indent=1,
                                                                                       default=str),
            "```", "", "</details>", ""]
    return "\n".join(out)


def write(path: str | os.PathLike[str], title: str, command: str, result: Any, lines: Sequence[str] = (),
          tables: Sequence[Table] = ()) -> Path:
    """Write :func:`render`'s page to ``path`` (replacing it) and return the path."""
    p = Path(path)
    p.write_text(render(title, command, result, lines, tables), encoding="utf-8")
    return p
