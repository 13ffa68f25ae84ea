"""Built-in candidate effects (entry-point group ``skinkit.effects``); see ``docs/guide/effects.md``.

* :mod:`.material`: ``viscoelastic``, ``prestress``, ``fibres`` (edits of the skin's law);
* :mod:`.fields`: ``layer-slip``, ``fascia``, ``inclusion``, ``preconditioning`` (``[[fields]]``);
* :mod:`.geometry`: ``thickness``, ``support-compliance`` (geometry and support);
* :mod:`.instrument`: ``indenter-tilt``, ``force-offset``, ``force-drift``, ``force-warmup``,
  ``force-wander``, ``channel-lag``, ``robot-compliance``, ``tracking-bias`` (``[[instrument]]`` entries).
"""
