"""Stereo vision engine: cameras, synthetic rig rendering, calibration, triangulation, 3D tracks.

Submodules (each one job):

- :mod:`skinkit.vision.texture`       speckle texture bound to material coordinates
- :mod:`skinkit.vision.sensor`        blur, illumination falloff, noise, quantisation
- :mod:`skinkit.vision.planar`        2D renders of a deformed speckle with exact truth
- :mod:`skinkit.vision.subsets`       subset extraction, NCC integer search, ISU, TrackResult
- :mod:`skinkit.vision.imageio`       reading images and point lists with clear errors
- :mod:`skinkit.vision.camera`        projection and back-projection through a CameraModel
- :mod:`skinkit.vision.rigs`          ring rigs like the thesis stereoscope
- :mod:`skinkit.vision.scene`         skin, boards, cone and markers seen by a rig; ground truth
- :mod:`skinkit.vision.boards`        checkerboard / ChArUco detection, rendered board views
- :mod:`skinkit.vision.calibration`   joint calibration of N cameras (OpenCV 5 multiview)
- :mod:`skinkit.vision.dotgrid`       dot-grid targets with fiducials (DIC style, OpenCV circle grids)
- :mod:`skinkit.vision.dotgrid_detect` dot-grid detection, ordering, orientation; calibration from it
- :mod:`skinkit.vision.matching`      SIFT seed correspondences checked against the epipolar geometry
- :mod:`skinkit.vision.triangulation` multi-view triangulation with reprojection errors
- :mod:`skinkit.vision.tracking3d`    2D tracks of profiled points -> SurfaceTrack
- :mod:`skinkit.vision.cone`          least-squares cone fit and indenter tip
- :mod:`skinkit.vision.markers`       marker sphere detection, matching and track validation
- :mod:`skinkit.vision.plots`         profile figures
"""

from skinkit.errors import SkinkitError


class VisionError(SkinkitError):
    """Bad input to a vision step (image, rig, board, points); the message names it."""


__all__ = ["VisionError"]
