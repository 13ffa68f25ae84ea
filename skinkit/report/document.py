"""The session report assembled: a contents list, then one section per kind of result the
experiment file holds (sections for what it lacks are left out and said so in the contents)."""

from __future__ import annotations

import os
from pathlib import Path

from skinkit.errors import StoreError
from skinkit.report import calibration, fits, gaps, images, lumped, profile, records, session, tracks
from skinkit.report.common import CSS, JS, Section, e
from skinkit.store import open_experiment


def sections(path: str | os.PathLike[str]) -> tuple[str, list[Section]]:
    """Read experiment file ``path`` (read-only) and build every section, in the report's order.
    Returns the file's name and the sections (omitted ones with ``html`` None).

    Raises :class:`skinkit.errors.StoreError` (one line) when the file is not an experiment file
    or is damaged.
    """
    with open_experiment(path, "r") as exp:
        summary = exp.summary()
        stored = {n: exp.read_fit(n) for n in exp.fit_names()}
        gap_reports = {n: exp.read_gap(n) for n in exp.gap_names()}
        out = [session.section(exp, summary), records.section(exp), lumped.section(exp, stored),
               calibration.section(exp), images.section(exp), profile.section(exp), tracks.section(exp),
               fits.section(stored, gap_reports), gaps.section(exp)]
    return Path(path).name, out


def _contents(parts: list[Section]) -> str:
    items = []
    for s in parts:
        if s.html is None:
            items.append(f'<li class="omitted">{e(s.title)} — {e(s.summary)}</li>')
        else:
            items.append(f'<li><a href="#{e(s.id)}">{e(s.title)}</a>: {e(s.summary)}</li>')
    return '<nav id="contents"><h2>Contents</h2><ol class="contents">' + "".join(items) + "</ol></nav>"


def render_report(path: str | os.PathLike[str]) -> str:
    """The report of experiment file ``path`` as one self-contained HTML document (a string):
    inline CSS and script, figures as PNG ``data:`` URIs, no external reference."""
    name, parts = sections(path)
    title = f"Session report: {name}"
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{e(title)}</title><style>{CSS}</style></head><body>"
            f"<h1>{e(title)}</h1><p class=\"sub\">Every result the experiment file holds, read from it alone "
            "(skinkit report).</p>" + _contents(parts) + "".join(s.render() for s in parts)
            + f"<script>{JS}</script></body></html>\n")


def default_out(session_path: str | os.PathLike[str]) -> Path:
    """``<session stem>-report.html`` in the current directory."""
    return Path.cwd() / f"{Path(session_path).stem}-report.html"


def write_report(session_path: str | os.PathLike[str], out: str | os.PathLike[str] | None = None, *,
                 overwrite: bool = False) -> Path:
    """Write the report of ``session_path`` to ``out`` (default :func:`default_out`) and return its
    path. The HTML is written to a temporary file next to ``out`` and renamed into place, so a
    failure leaves no half-written report.

    Raises :class:`StoreError` when ``out`` exists and ``overwrite`` is false, is a folder, or
    cannot be written, and when the session file is not a readable experiment file.
    """
    open_experiment(session_path, "r").close()   # a bad session file is said before anything else
    target = Path(out) if out is not None else default_out(session_path)
    if target.is_dir():
        raise StoreError(str(target), "", "is a folder; give the HTML file's path")
    if target.exists() and not overwrite:
        raise StoreError(str(target), "", "already exists (pass --overwrite to replace it)")
    if Path(session_path).resolve() == target.resolve():
        raise StoreError(str(target), "", "is the session file itself; give another output path")
    text = render_report(session_path)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        # not mkstemp: its 0600 mode would survive the rename, and a report is made to be shared
        tmp = target.parent / f".{target.name}.{os.getpid()}.tmp"
        try:
            tmp.write_text(text, encoding="utf-8")
            os.replace(tmp, target)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
    except OSError as exc:
        raise StoreError(str(target), "", f"cannot write the report: {exc.strerror or exc}") from None
    return target
