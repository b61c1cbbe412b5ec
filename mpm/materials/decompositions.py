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


@functools.cache
def make_svd(t: Types):
    S = t.scalar
    vec, mat = t.vec, t.mat

    if t.dim == 2:
        rotation = make_rotation(t)

        @wp.func
        def svd(F: t.mat):
            # closed form (wp.svd2 is wrong for equal singular values): the
            # polar rotation R, then the eigenvectors of the symmetric S = R^T F
            R = rotation(F)
            Sym = wp.transpose(R) * F
            a = Sym[0, 0]
            b = S(0.5) * (Sym[0, 1] + Sym[1, 0])
            c = Sym[1, 1]
            phi = S(0.5) * wp.atan2(S(2.0) * b, a - c)
            co = wp.cos(phi)
            si = wp.sin(phi)
            mean = S(0.5) * (a + c)
            r = wp.sqrt(S(0.25) * (a - c) * (a - c) + b * b)
            V = mat(co, -si, si, co)
            return R * V, vec(mean + r, mean - r), V

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
