"""What the CLI tests share: the contract of a refused command (exit 2, one ``error:`` line)."""

from __future__ import annotations

from typing import Any


def one_error(r: Any, *needles: str, warnings_ok: bool = False) -> str:
    """Assert that the click result ``r`` is a refusal: exit status 2, no traceback, and exactly one
    ``error: `` line on stderr holding every ``needle`` (``warnings_ok``: ``warning:`` lines may
    precede it). Returns that line."""
    assert r.exit_code == 2, (r.exit_code, r.output)
    assert "Traceback" not in r.output
    lines = [ln for ln in r.stderr.splitlines()
             if ln.strip() and not (warnings_ok and ln.startswith("warning:"))]
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]
