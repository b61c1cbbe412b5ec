"""The implicit integrator: backward Euler on the grid velocities solved by
Newton's method (:mod:`.solve`) and the kernels of its system
(:mod:`.system`)."""
