"""Sweeps: the end of a multirun (``callback``: the report and the jobs per
status)."""
