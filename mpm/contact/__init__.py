"""Contact between bodies: the explicit step's passes (:mod:`.passes`), the
implicit solve's constraints (:mod:`.constraint`) and the lattice reads both
share (:mod:`.lattice`)."""
