"""Export a run's recorded particle frames for other tools:
``python -m pipelines.export <run dir> --format vtk|usd [--every N] [--out DIR]``.

``vtk``: a ``.vtp`` per frame and ``particles.pvd``, the time series
ParaView opens as one, with every logged channel as point data; ``usd``: a
stage with time-sampled points and a primvar per channel. Both with the
walls and colliders as surfaces (:mod:`pipelines.export.command`)."""
