"""Built-in surface profilers (entry-point group ``skinkit.profilers``)."""
