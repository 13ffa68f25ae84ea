"""Side-by-side benchmarks (``skinkit bench ...``)."""
