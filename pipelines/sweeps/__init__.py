"""Sweeps: the end of a multirun (``callback``: the report and the jobs per
status) and the stability-map jobs (``stability``)."""
