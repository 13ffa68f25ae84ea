"""Optimiser plugins (``skinkit.optimisers``)."""
