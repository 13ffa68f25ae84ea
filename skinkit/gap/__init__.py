"""Sim-to-real gap diagnosis (issue 11)."""
