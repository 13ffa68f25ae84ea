"""Driver plugins registered under ``skinkit.drivers``: ``sim``, ``serial``, ``can``."""
