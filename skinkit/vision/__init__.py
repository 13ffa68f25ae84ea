"""Stereo vision engine: cameras, synthetic rig rendering, calibration, triangulation, 3D tracks.

Submodules (each one job):

- :mod:`skinkit.vision.texture`       speckle texture bound to material coordinates
- :mod:`skinkit.vision.sensor`        blur, illumination falloff, noise, quantisation
- :mod:`skinkit.vision.planar`        2D renders of a deformed speckle with exact truth
- :mod:`skinkit.vision.subsets`       subset extraction, NCC integer search, track results
- :mod:`skinkit.vision.camera`        projection and back-projection through a CameraModel
- :mod:`skinkit.vision.rigs`          ring rigs like the thesis stereoscope
- :mod:`skinkit.vision.scene`         surfaces, boards, cones and markers seen by a rig
- :mod:`skinkit.vision.calibration`   checkerboard detection and joint rig calibration
- :mod:`skinkit.vision.triangulation` multi-view triangulation with reprojection errors
- :mod:`skinkit.vision.tracking3d`    2D tracks of profiled points -> SurfaceTrack
- :mod:`skinkit.vision.cone`          least-squares cone fit and indenter tip
- :mod:`skinkit.vision.markers`       marker sphere detection and validation
"""

from skinkit.errors import SkinkitError


class VisionError(SkinkitError):
    """Bad input to a vision step (image, rig, board, points); the message names it."""


__all__ = ["VisionError"]
