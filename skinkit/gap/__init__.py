"""Sim-to-real gap diagnosis: where a calibrated model misses a session, which
unmodelled effect causes it, and how far the gap shrinks once that effect is added.

* :mod:`skinkit.gap.where` — step 1: the noise-normalised residual by protocol, channel, phase,
  region and frequency, each cell tested against the noise;
* :mod:`skinkit.gap.score` — step 2: score (Lagrange-multiplier) tests of every candidate effect
  at its null from one prediction with sensitivities, and which effects are separable;
* :mod:`skinkit.gap.diagnose` — steps 2-3: refits of the best candidates, the naming rule, the
  shrinkage; :func:`diagnose` is the library entry point and returns a
  :class:`skinkit.schemas.GapReport` (step 4; ``skinkit gap diagnose``, step 5);
* :mod:`skinkit.gap.html` — the self-contained HTML report.

``docs/guide/gap-diagnosis.md`` describes the method and its rules.
"""

from skinkit.gap.diagnose import AIC_MARGIN, GapError, diagnose, write_report

__all__ = ["AIC_MARGIN", "GapError", "diagnose", "write_report"]
