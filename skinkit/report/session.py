"""The report's first section: the file and the session's metadata."""

from __future__ import annotations

from typing import Any

from skinkit.report.common import Section, kv_table, note, value_text
from skinkit.store.experiment import Experiment
from skinkit.store.layout import created_text


def _text(v: Any) -> str:
    if hasattr(v, "tolist"):
        v = v.tolist()
    if isinstance(v, bytes):
        v = v.decode("utf-8", "replace")
    return value_text(v, 6)


def section(exp: Experiment, summary: dict[str, Any]) -> Section:
    """The file (path, schema, writer, creation time, whether its writer closed it) and the free
    metadata of ``/session``; ``summary`` is :meth:`Experiment.summary`. Always present."""
    rows = [("file", str(summary["path"])), ("schema version", str(summary["schema_version"])),
            ("written by", f"skinkit {summary['skinkit_version']}"),
            ("created", created_text(str(summary["created"]))),
            ("closed cleanly by its writer", "yes" if summary["closed_cleanly"] else
             "no (the writer died; unfinished records are marked incomplete)")]
    meta = exp.metadata()
    body = '<div class="meta">' + kv_table(rows) + "</div>"
    if meta:
        body += "<h3>Session metadata</h3>" + '<div class="meta">' + kv_table(
            (str(k), _text(v)) for k, v in meta.items()) + "</div>"
    else:
        body += note("The file stores no session metadata (/session).")
    who = ", ".join(f"{k} {_text(meta[k])}" for k in ("subject", "site") if k in meta)
    return Section("session", "Session", body, who or "file and metadata")
