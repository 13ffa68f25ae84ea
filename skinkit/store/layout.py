"""The experiment file layout (one HDF5 file per session), version 1.

::

    /                         attrs: format="skinkit-experiment", schema_version="1.0",
                                     skinkit_version, created (ISO 8601 UTC)
    /session                  attrs: free metadata (subject, site, operator, notes, ...)
    /records/<protocol>/      one robot record per protocol run
        attrs: protocol (JSON of skinkit.schemas.Protocol), rate_hz (nominal),
               channels (JSON list), complete (bool: the writer closed it),
               [extra (JSON object: facts about the run, e.g. the link's samples_lost)]
        time_s      (N,)   float64  [s]
        <channel>   (N, 3) float64  unit in the dataset's "unit" attribute, one of
                                    RobotRecord.CHANNELS (motor_position m, motor_current A,
                                    motor_force N, tip_position m, tip_force N, tip_torque N m)
        flags       (N,)   uint32   RobotRecord FLAG_* bits
        committed   (1,)   int64    samples whose block was completely written and flushed;
                                    readers ignore rows past it (a block cut by a crash)
    /rig/cameras/<name>/      K (3,3) px, distortion (k,), R (3,3), t (3,) m; attrs image_size
    /images/<sequence>/       frames (F, C, H, W) uint8|uint16|float, time_s (F,);
                              attrs camera_names (JSON list), complete (bool)
    /profiles/<name>/         points (N,3) m, quality (N,), [uncertainty_px (N,)];
                              attrs quality_name
    /tracks/<name>/           points (P,F,3) m, valid (P,F) bool, time_s (F,), [point_ids (P,)]
    /calibrations/<name>      attrs json (a device calibration, e.g. "robot")
    /fits/<name>              attrs json (skinkit.schemas.FitResult.to_dict)
    /gaps/<name>              attrs json (skinkit.schemas.GapReport.to_dict)
    /attempts/<NNNN>          a run that failed before or while recording (numbered from 0001):
                              attrs protocol (JSON of the Protocol), json (the facts: driver,
                              stage, reason, started, samples, ...)

Records are appended block by block in HDF5's single-writer/multiple-reader (SWMR) mode,
which orders metadata writes so that the file stays consistent whatever moment the writer
dies at; ``committed`` is updated after each block's data are flushed.
"""

from __future__ import annotations

from datetime import datetime

FORMAT = "skinkit-experiment"
SCHEMA_VERSION = "1.0"
#: major versions this reader understands
SUPPORTED_MAJOR = {1}

RECORDS = "records"
RIG = "rig/cameras"
IMAGES = "images"
PROFILES = "profiles"
TRACKS = "tracks"
FITS = "fits"
CALIBRATIONS = "calibrations"
GAPS = "gaps"
ATTEMPTS = "attempts"
SESSION = "session"


def created_text(stamp: str) -> str:
    """The ``created`` attribute (an ISO 8601 time stamp) to the second, for people:
    ``"2026-11-24 09:12:03 UTC"`` (UTC when the stamp says so; a stamp that does not parse is
    returned as it is)."""
    try:
        t = datetime.fromisoformat(stamp)
    except ValueError:
        return stamp
    zone = " UTC" if t.utcoffset() is not None and t.utcoffset().total_seconds() == 0 else ""
    return t.strftime("%Y-%m-%d %H:%M:%S") + zone
