"""Surface profiles and tracks in an experiment file (``/profiles``, ``/tracks`` of
:mod:`skinkit.store.layout`)."""

from __future__ import annotations

from typing import Any

from skinkit.errors import SchemaError
from skinkit.schemas import SurfaceProfile, SurfaceTrack
from skinkit.store import layout as L
from skinkit.store.h5file import ExperimentFile, reading, text


class SurfaceAccess(ExperimentFile):
    """The surface profiles and tracks of an experiment file."""

    # -- surfaces ------------------------------------------------------------------------
    def write_profile(self, name: str, profile: SurfaceProfile) -> None:
        """Store (replace) the surface profile ``name``: points (N, 3) [m], quality, uncertainty [px]."""
        g = self._replace_group(L.PROFILES, name)
        g.create_dataset("points", data=profile.points).attrs["unit"] = "m"
        g.create_dataset("quality", data=profile.quality)
        if profile.uncertainty_px is not None:
            g.create_dataset("uncertainty_px", data=profile.uncertainty_px).attrs["unit"] = "px"
        g.attrs["quality_name"] = profile.quality_name
        self._f.flush()

    @reading
    def profile_names(self) -> list[str]:
        """The names of the stored surface profiles."""
        return sorted(self._f[L.PROFILES]) if L.PROFILES in self._f else []

    @reading
    def read_profile(self, name: str) -> SurfaceProfile:
        """The surface profile ``name``."""
        g = self._group(f"{L.PROFILES}/{name}")
        try:
            return SurfaceProfile(
                points=self._dataset(g, "points", 2, last=3, unit="m")[()],
                quality=self._dataset(g, "quality", 1)[()],
                uncertainty_px=g["uncertainty_px"][()] if "uncertainty_px" in g else None,
                quality_name=self._attr(g, "quality_name", text, "peak_correlation", "a name"))
        except SchemaError as exc:
            raise self._err(g.name, str(exc)) from None

    def write_track(self, name: str, track: SurfaceTrack) -> None:
        """Store (replace) the surface track ``name``: points (P, F, 3) [m], valid (P, F), times (F,)
        [s], and the per-position standard errors (P, F, 3) [m] when the track has them."""
        g = self._replace_group(L.TRACKS, name)
        g.create_dataset("points", data=track.points, chunks=True).attrs["unit"] = "m"
        g.create_dataset("valid", data=track.valid)
        g.create_dataset("time_s", data=track.time_s).attrs["unit"] = "s"
        if track.point_ids is not None:
            g.create_dataset("point_ids", data=track.point_ids)
        if track.uncertainty_m is not None:
            g.create_dataset("uncertainty", data=track.uncertainty_m, chunks=True).attrs["unit"] = "m"
        self._f.flush()

    @reading
    def track_names(self) -> list[str]:
        """The names of the stored surface tracks."""
        return sorted(self._f[L.TRACKS]) if L.TRACKS in self._f else []

    def set_track_attrs(self, name: str, **items: Any) -> None:
        """Attach JSON-ready facts to track ``name`` (e.g. its producer's ``noise_m`` [m] per
        axis, ``dimensions``), merged into its ``extra`` attribute."""
        self._merge_extra(L.TRACKS, "track", name, items)

    @reading
    def track_attrs(self, name: str) -> dict[str, Any]:
        """The facts attached to track ``name`` by :meth:`set_track_attrs` (empty if none)."""
        g = self._group(f"{L.TRACKS}/{name}")
        return self._json_attr(g, "extra", dict) if "extra" in g.attrs else {}

    @reading
    def read_track(self, name: str) -> SurfaceTrack:
        """The surface track ``name``."""
        g = self._group(f"{L.TRACKS}/{name}")
        try:
            return SurfaceTrack(
                points=self._dataset(g, "points", 3, last=3, unit="m")[()],
                valid=self._dataset(g, "valid", 2)[()],
                time_s=self._dataset(g, "time_s", 1, unit="s")[()],
                point_ids=g["point_ids"][()] if "point_ids" in g else None,
                uncertainty_m=(self._dataset(g, "uncertainty", 3, last=3, unit="m")[()]
                               if "uncertainty" in g else None))
        except SchemaError as exc:
            raise self._err(g.name, str(exc)) from None

