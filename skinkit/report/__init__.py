"""The session report: one self-contained HTML file with every result an experiment
file holds — metadata, robot records, lumped fits, calibration, images, surface profiles,
tracks, model fits with their identifiability, and gap reports (``skinkit report``).

One module per kind of section (:mod:`~skinkit.report.records`, :mod:`~skinkit.report.lumped`,
:mod:`~skinkit.report.calibration`, :mod:`~skinkit.report.images`, :mod:`~skinkit.report.profile`,
:mod:`~skinkit.report.tracks`, :mod:`~skinkit.report.fits`, :mod:`~skinkit.report.gaps`); each
returns a :class:`~skinkit.report.common.Section`, None-bodied when the file has nothing for it.
:mod:`~skinkit.report.document` puts them together.
"""

from skinkit.report.document import default_out, render_report, sections, write_report

__all__ = ["default_out", "render_report", "sections", "write_report"]
