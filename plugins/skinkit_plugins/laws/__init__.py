"""Built-in constitutive laws (entry-point group ``skinkit.laws``)."""
