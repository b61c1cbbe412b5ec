"""One run: the command line ``python -m pipelines.run`` (``__main__``: Hydra
composes, the config is validated, finished sweep jobs are skipped), the run
loop (``runner``), its progress bar (``progress``), what it records to be
reproduced (``provenance``) and Warp's set-up for the command line
(``warp_setup``)."""
