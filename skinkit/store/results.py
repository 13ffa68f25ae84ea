"""Results and calibrations stored as JSON in an experiment file (``/fits``, ``/gaps``,
``/calibrations`` of :mod:`skinkit.store.layout`)."""

from __future__ import annotations

from typing import Any

from skinkit import jsonio
from skinkit.errors import SchemaError
from skinkit.schemas import FitResult, GapReport
from skinkit.store import layout as L
from skinkit.store.h5file import ExperimentFile, one_line, reading


class ResultAccess(ExperimentFile):
    """The fit results, gap reports and device calibrations of an experiment file."""

    # -- results -------------------------------------------------------------------------
    def _write_json(self, base: str, name: str, payload: dict[str, Any]) -> None:
        g = self._replace_group(base, name)
        g.attrs["json"] = jsonio.dumps(payload, allow_nan=True)
        self._f.flush()

    def write_fit(self, name: str, fit: FitResult) -> None:
        """Store (replace) the fit result ``name`` as JSON."""
        self._write_json(L.FITS, name, fit.to_dict())

    @reading
    def fit_names(self) -> list[str]:
        """The names of the stored fit results."""
        return sorted(self._f[L.FITS]) if L.FITS in self._f else []

    @reading
    def read_fit(self, name: str) -> FitResult:
        """The fit result ``name``."""
        g = self._group(f"{L.FITS}/{name}")
        try:
            return FitResult.from_dict(self._json_attr(g, "json", dict))
        except (SchemaError, TypeError, KeyError) as exc:
            raise self._err(g.name, f"malformed fit result ({one_line(exc)})") from None

    def write_gap(self, name: str, report: GapReport) -> None:
        """Store (replace) the gap report ``name`` as JSON."""
        self._write_json(L.GAPS, name, report.to_dict())

    @reading
    def gap_names(self) -> list[str]:
        """The names of the stored gap reports."""
        return sorted(self._f[L.GAPS]) if L.GAPS in self._f else []

    @reading
    def read_gap(self, name: str) -> dict[str, Any]:
        """The gap report ``name`` as its JSON dict."""
        return self._json_attr(self._group(f"{L.GAPS}/{name}"), "json", dict)

    def write_calibration(self, name: str, payload: dict[str, Any]) -> None:
        """Store (replace) a device calibration ``name`` (e.g. ``"robot"``) as JSON."""
        self._write_json(L.CALIBRATIONS, name, payload)

    @reading
    def calibration_names(self) -> list[str]:
        """The names of the stored device calibrations."""
        return sorted(self._f[L.CALIBRATIONS]) if L.CALIBRATIONS in self._f else []

    @reading
    def read_calibration(self, name: str) -> dict[str, Any]:
        """The calibration ``name`` as its JSON dict."""
        return self._json_attr(self._group(f"{L.CALIBRATIONS}/{name}"), "json", dict)

