"""A run's data: the sinks a run writes to (``sinks``, the Rerun sink
``rerun_sink`` and the colliders' drawable ``surfaces``), reading
recordings back (``recordings``) and showing them (``replay``: the viewer
and PNG frames)."""
