"""Decompositions of a deformation gradient F.

* ``svd(F) -> (U, sigma, V)``: F = U diag(sigma) V^T with proper rotations U
  and V (det = +1) and the singular values in descending order; an inverted F
  (det F < 0) carries its sign on the last, smallest one. Every isotropic
  model here works on ``sigma`` (principal stretches) and rotates back.
* ``rotation(F) -> R``: the rotation of the polar decomposition F = R S, the
  proper rotation that maximises tr(R^T F). 2D: closed form. 3D: scaled
  Newton iteration for det F > 0, the SVD's U V^T otherwise.
"""

import functools

import numpy as np
import warp as wp

from ..types import Types


@functools.cache
def make_rotation(t: Types):
    S = t.scalar
    mat = t.mat

    if t.dim == 2:

        @wp.func
        def rotation(F: t.mat):  # pyright: ignore[reportRedeclaration]
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
    cofactor = make_cofactor(t)
    # squared Frobenius change below which the iterate is converged: Newton's
    # error after a step of size d is about d^2 / 2, so d^2 < eps leaves the
    # next error below machine epsilon
    tol = float(np.finfo(np.float32 if t.precision == "float32" else np.float64).eps)

    @wp.func
    def rotation(F: t.mat):
        # Higham's Newton iteration for the polar factor (Higham 1986),
        #   X_{k+1} = (g X_k + X_k^-T / g) / 2,  X_0 = F,  X^-T = cof(X) / det X,
        # with the determinant scaling g = |det X_k|^(-1/3) while the steps
        # are large. It converges quadratically to the orthogonal factor,
        # which is a proper rotation when det F > 0: 3-6 iterations for
        # F = Q (I + E) with E of standard deviation up to 0.3, about 4x
        # cheaper than wp.svd3 and accurate to round-off (float32 wp.svd3
        # misses that rotation by up to 7e-3). An inverted or degenerate F,
        # where the closest rotation flips the weakest direction, takes the
        # sign-fixed SVD.
        X = F
        converged = bool(False)
        if wp.determinant(F) > S(0.0):
            change = S(1.0)
            for _k in range(MAX_NEWTON):
                cof = cofactor(X)
                d = X[0, 0] * cof[0, 0] + X[0, 1] * cof[0, 1] + X[0, 2] * cof[0, 2]
                g = S(1.0)
                if change > S(1.0e-2):
                    g = wp.pow(d, S(MINUS_ONE_THIRD))
                Y = S(0.5) * (g * X + cof / (g * d))
                D = Y - X
                X = Y
                change = wp.ddot(D, D)
                if change < S(tol):
                    converged = True
                    break
        if not converged:
            U, sig, V = svd(F)
            X = U * wp.transpose(V)
        return X

    return rotation


# Newton iterations of the 3D polar rotation before the SVD takes over
MAX_NEWTON = 16
MINUS_ONE_THIRD = -1.0 / 3.0  # a Python float: inside a Warp function the quotient would be float32


@functools.cache
def make_cofactor(t: Types):
    """cof(X) = det(X) X^-T of a 3x3 matrix (the transposed adjugate)."""

    @wp.func
    def cofactor(X: t.mat):
        return t.mat(
            X[1, 1] * X[2, 2] - X[1, 2] * X[2, 1], X[1, 2] * X[2, 0] - X[1, 0] * X[2, 2],
            X[1, 0] * X[2, 1] - X[1, 1] * X[2, 0],
            X[0, 2] * X[2, 1] - X[0, 1] * X[2, 2], X[0, 0] * X[2, 2] - X[0, 2] * X[2, 0],
            X[0, 1] * X[2, 0] - X[0, 0] * X[2, 1],
            X[0, 1] * X[1, 2] - X[0, 2] * X[1, 1], X[0, 2] * X[1, 0] - X[0, 0] * X[1, 2],
            X[0, 0] * X[1, 1] - X[0, 1] * X[1, 0])

    return cofactor


@functools.cache
def make_svd(t: Types):
    S = t.scalar
    vec, mat = t.vec, t.mat

    if t.dim == 2:
        rotation = make_rotation(t)

        @wp.func
        def svd(F: t.mat):  # pyright: ignore[reportRedeclaration]
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

        return svd  # pyright: ignore[reportGeneralTypeIssues]

    @wp.func
    def svd(F: t.mat):
        # wp.svd3 already returns proper rotations, the sign on the last sigma
        U = mat()
        sig = vec()
        V = mat()
        wp.svd3(F, U, sig, V)
        return U, sig, V

    return svd
