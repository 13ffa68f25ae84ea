"""Built-in 2D subset trackers (entry-point group ``skinkit.trackers``)."""
