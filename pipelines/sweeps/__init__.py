"""Sweeps: the stability-map jobs (``stability``)."""
