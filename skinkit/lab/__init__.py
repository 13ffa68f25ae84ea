"""The virtual lab: synthetic sessions whose truth is known, for running skinkit with no robot."""
