"""Decompositions of a deformation gradient F.

* ``svd(F) -> (U, sigma, V)``: F = U diag(sigma) V^T with proper rotations U
  and V (det = +1) and the singular values in descending order; an inverted F
  (det F < 0) carries its sign on the last, smallest one. Every isotropic
  model here works on ``sigma`` (principal stretches) and rotates back.
* ``rotation(F) -> R``: the rotation of the polar decomposition F = R S.
"""

import functools

import warp as wp

from ..types import Types


@functools.cache
def make_svd(t: Types):
    S = t.scalar
    vec, mat = t.vec, t.mat

    if t.dim == 2:

        @wp.func
        def svd(F: t.mat):
            U = mat()
            sig = vec()
            V = mat()
            wp.svd2(F, U, sig, V)
            # wp.svd2 keeps sigma >= 0 and V proper; move a reflection of U onto sigma
            if wp.determinant(U) < S(0.0):
                U = mat(U[0, 0], -U[0, 1], U[1, 0], -U[1, 1])
                sig = vec(sig[0], -sig[1])
            return U, sig, V

        return svd

    @wp.func
    def svd(F: t.mat):
        # wp.svd3 already returns proper rotations, the sign on the last sigma
        U = mat()
        sig = vec()
        V = mat()
        wp.svd3(F, U, sig, V)
        return U, sig, V

    return svd


@functools.cache
def make_rotation(t: Types):
    S = t.scalar
    mat = t.mat

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

    svd = make_svd(t)

    @wp.func
    def rotation(F: t.mat):
        U, sig, V = svd(F)
        return U * wp.transpose(V)

    return rotation
