"""A run's configuration, each group defined once: how a group is defined
and the checks derived from it (``fields``), the groups (``physics``: the
solver's own classes; ``settings``: run, log, kernel, stability map;
``scene``, ``shapes``, ``colliders``), the root and Hydra's ConfigStore
(``schema``), their resolution into the solver's dataclasses
(``validate``) and the one-line messages for configuration errors
(``errors``)."""
