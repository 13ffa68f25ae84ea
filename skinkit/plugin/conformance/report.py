"""The report every conformance kit returns: named checks, each passed or failed with a reason."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class Check:
    """One check: its name, outcome and a one-line detail (why it failed, or what it measured)."""

    name: str
    passed: bool
    detail: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The check as a plain dict (JSON-ready)."""
        return {"name": self.name, "passed": self.passed, "detail": self.detail}


@dataclass
class Report:
    """All checks of one plugin of kind ``kind`` (``"effect"``, ``"tracker"``, ...) named ``name``;
    ``passed`` when every check passed."""

    kind: str
    name: str
    checks: list[Check] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        """True when every check passed."""
        return all(c.passed for c in self.checks)

    @property
    def failed(self) -> list[Check]:
        """The checks that failed."""
        return [c for c in self.checks if not c.passed]

    def add(self, name: str, passed: bool, detail: str = "") -> bool:
        """Record a check; returns ``passed`` (so a kit can stop when a prerequisite failed)."""
        self.checks.append(Check(name, bool(passed), detail))
        return bool(passed)

    def to_dict(self) -> dict[str, Any]:
        """The report as a plain dict (JSON-ready)."""
        return {"kind": self.kind, "name": self.name, "passed": self.passed,
                "checks": [c.to_dict() for c in self.checks]}

    def __str__(self) -> str:
        lines = [f"{self.kind} {self.name}: {'PASS' if self.passed else 'FAIL'}"]
        lines += [f"  {'ok  ' if c.passed else 'FAIL'} {c.name}" + (f": {c.detail}" if c.detail else "")
                  for c in self.checks]
        return "\n".join(lines)


__all__ = ["Check", "Report"]
