"""A gap report's files: ``gap.json`` and, with the HTML extra, ``gap.html``."""

from __future__ import annotations

import os
from pathlib import Path

from skinkit import jsonio
from skinkit.schemas import GapReport


def write_report(report: GapReport, out_dir: str | os.PathLike[str]) -> list[Path]:
    """``gap.json`` (and ``gap.html`` when :mod:`skinkit.gap.html` is installed) in ``out_dir``."""

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    d = report.to_dict()
    path = out / "gap.json"
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(jsonio.dumps(d, indent=2, allow_nan=False))
    os.replace(tmp, path)
    written = [path]
    try:
        from skinkit.gap.html import write_html
    except ImportError:
        return written
    written.append(Path(write_html(d, out / "gap.html") or out / "gap.html"))
    return written


__all__ = ["write_report"]
