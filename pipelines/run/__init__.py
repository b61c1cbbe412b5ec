"""One run: the command line ``python -m pipelines.run`` (``__main__``: Hydra
composes, the config is validated, finished sweep jobs are skipped), the run
loop (``runner``), its progress bar (``progress``), what it records to be
reproduced (``provenance``), Warp's set-up for the command line
(``warp_setup``), the stability-map job that runs its points in place of one
run (``stability_map``) and the jobs per status of this process's multiruns
(``multiruns``)."""
