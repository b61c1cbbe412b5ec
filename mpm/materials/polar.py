"""Rotation part R of the polar decomposition F = R S (det R = +1)."""

import functools

import warp as wp

from ..types import Types


@functools.cache
def make_rotation(t: Types):
    S = t.scalar
    vec, mat = t.vec, t.mat

    if t.dim == 2:

        @wp.func
        def rotation(F: t.mat):
            # closed form: R = [[c, -s], [s, c]] maximises tr(R^T F)
            a = F[0, 0] + F[1, 1]
            b = F[1, 0] - F[0, 1]
            r = wp.sqrt(a * a + b * b)
            c = S(1.0)
            s = S(0.0)
            if r > S(0.0):
                c = a / r
                s = b / r
            return mat(c, -s, s, c)

        return rotation

    @wp.func
    def rotation(F: t.mat):
        U = mat()
        sig = vec()
        V = mat()
        wp.svd3(F, U, sig, V)
        # keep R a proper rotation: flip the weakest direction if needed
        if wp.determinant(U) < S(0.0):
            U = U * wp.diag(vec(S(1.0), S(1.0), S(-1.0)))
        if wp.determinant(V) < S(0.0):
            V = V * wp.diag(vec(S(1.0), S(1.0), S(-1.0)))
        return U * wp.transpose(V)

    return rotation
