"""The benchmark, ``python -m pipelines.bench`` (``__main__``: the tables and
the command line): the speed of the solver, of logging and of configuration
updates; the papers' scale, growth with size and the optional stages
(``scale``); the runs every table shares (``runs``)."""
