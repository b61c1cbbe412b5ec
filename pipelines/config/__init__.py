"""A run's configuration: the schemas registered with Hydra (``schema``),
their validation into the solver's dataclasses (``validate``) and the
one-line messages for configuration errors (``errors``)."""
