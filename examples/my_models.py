"""A material model and an interpolation kernel defined outside ``mpm``:
copies of the built-in neo-Hookean solid and quadratic B-spline under names
of their own, registered so that the command line and every lookup by name
know them (docs/extending.md walks through this file).

    python examples/my_models.py [--steps 48] [--resolution 24] [--device cpu]   # each copy against the built-in it copies: the same bits
    python -m pipelines.run material=examples.my_models.MyNeoHookean kernel=examples.my_models.MY_QUADRATIC
"""

import functools
from dataclasses import dataclass

import numpy as np
import warp as wp

import mpm
from mpm.kernels import register_kernel
from mpm.materials import register_material
from mpm.materials.base import elastic_wave_speed, lame
from mpm.params import param
from mpm.types import Types


# ---------------------------------------------------------------- the material
# P = mu (F - F^-T) + lambda ln(J) F^-T,
# psi = mu/2 (tr(F^T F) - d) - mu ln J + lambda/2 (ln J)^2, with params = (mu, lambda) [Pa].
@functools.cache
def my_stress_energy(t: Types):
    """``stress_energy(F, L, params) -> (P [Pa], psi [J/m^3])`` for the
    dimension and precision of ``t`` (L, the velocity gradient, unused)."""
    S = t.scalar
    d = float(t.dim)

    @wp.func
    def stress_energy(F: t.mat, L: t.mat, params: t.params):
        mu = params[0]
        lam = params[1]
        FinvT = wp.transpose(wp.inverse(F))
        lnJ = wp.log(wp.determinant(F))
        P = mu * (F - FinvT) + lam * lnJ * FinvT
        psi = S(0.5) * mu * (wp.ddot(F, F) - S(d)) - mu * lnJ + S(0.5) * lam * lnJ * lnJ
        return P, psi

    return stress_energy


@functools.cache
def my_principal(t: Types):
    """``principal(sigma, params, history) -> (P_hat [Pa], psi [J/m^3], H)``:
    the same energy in the principal stretches sigma, with its Hessian H (the
    implicit integrator's tangent)."""
    S = t.scalar
    vec, mat = t.vec, t.mat
    dim = t.dim

    @wp.func
    def principal(sigma: t.vec, params: t.params, history: t.history):
        mu = params[0]
        lam = params[1]
        J = sigma[0]
        for i in range(1, wp.static(dim)):
            J = J * sigma[i]
        lnJ = wp.log(J)
        P = vec()
        H = mat()
        for i in range(wp.static(dim)):
            P[i] = mu * (sigma[i] - S(1.0) / sigma[i]) + lam * lnJ / sigma[i]
            for j in range(wp.static(dim)):
                H[i, j] = lam / (sigma[i] * sigma[j])
            H[i, i] = H[i, i] + mu + (mu - lam * lnJ) / (sigma[i] * sigma[i])
        psi = S(0.5) * mu * (wp.dot(sigma, sigma) - S(dim)) - mu * lnJ + S(0.5) * lam * lnJ * lnJ
        return P, psi, H

    return principal


@register_material
@dataclass
class MyNeoHookean(mpm.Material):
    """Compressible neo-Hookean solid (a copy of mpm's ``neo_hookean``)."""

    name = "my_neo_hookean"
    stress_energy = staticmethod(my_stress_energy)
    principal = staticmethod(my_principal)

    E: float = param(1.0e5, "Young's modulus [Pa]", gt=0.0)
    nu: float = param(0.3, "Poisson's ratio [-]", gt=-1.0, lt=0.5)

    def packed(self):
        return lame(self.E, self.nu)  # (mu, lambda) [Pa]: params[0], params[1] in the Warp functions

    def wave_speed(self, J: float = 1.0):
        return elastic_wave_speed(self.E, self.nu, self.rho)  # [m/s], for the stable time step


# ---------------------------------------------------------------- the kernel
# Quadratic B-spline, 3 nodes per axis; with u = x/dx - base in [0.5, 1.5):
# w = (1/2 (3/2 - u)^2, 3/4 - (u - 1)^2, 1/2 (u - 1/2)^2).
@functools.cache
def my_weights(t: Types):
    S = t.scalar
    W = wp.types.vector(3, S)

    @wp.func
    def weights(u: S):
        a = S(1.5) - u
        b = u - S(1.0)
        c = u - S(0.5)
        return W(S(0.5) * a * a, S(0.75) - b * b, S(0.5) * c * c)

    return weights


@functools.cache
def my_gradients(t: Types):
    S = t.scalar
    W = wp.types.vector(3, S)

    @wp.func
    def gradients(u: S):
        return W(u - S(1.5), S(-2.0) * (u - S(1.0)), u - S(0.5))

    return gradients


MY_QUADRATIC = register_kernel(mpm.Kernel(
    name="my_quadratic", support=3, offset=0.5, moment=0.25, margin=1.0,
    weights=my_weights, gradients=my_gradients,
))


# ---------------------------------------------------------------- a run from Python
def drop(material: mpm.Material, kernel: mpm.Kernel, steps: int = 48, resolution: int = 24,
         device: str = "cpu") -> mpm.State:
    """A disc of ``material`` (radius 0.1 m) dropped in a 1 m box for
    ``steps`` adaptive steps with ``kernel``; returns the final state."""
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=resolution, gravity=(0.0, -9.81),
                      bodies=[mpm.Body(mpm.Sphere((0.5, 0.24), 0.1), material, velocity=(0.0, -2.0))])
    model, state = mpm.build(scene, kernel, "float32", device)
    solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(track_energy=True))
    driver = mpm.Driver(solver, state, mpm.StepPolicy(steps=steps))
    outcome = driver.run()
    assert outcome.status == "completed", outcome.reason
    return state


FIELDS = ("x", "v", "C", "F0s", "Fsn")  # positions, velocities, affine matrices, deformation gradients


def compare(steps: int = 48, resolution: int = 24, device: str = "cpu") -> dict[str, list[str]]:
    """Each copy against the built-in it copies, on the disc of :func:`drop`:
    ``my_neo_hookean`` (with the quadratic kernel) against ``neo_hookean``,
    ``my_quadratic`` (with neo_hookean) against ``quadratic``; returns, per
    copy, the fields of the final state whose bits differ (none, on the CPU)."""
    built_in = drop(mpm.NeoHookean(), mpm.KERNELS["quadratic"], steps, resolution, device)
    runs = {"my_neo_hookean": drop(mpm.MATERIALS["my_neo_hookean"](), mpm.KERNELS["quadratic"], steps, resolution,
                                   device),
            "my_quadratic": drop(mpm.NeoHookean(), mpm.KERNELS["my_quadratic"], steps, resolution, device)}
    return {name: [f for f in FIELDS if not np.array_equal(getattr(state, f).numpy(), getattr(built_in, f).numpy())]
            for name, state in runs.items()}


def main(argv=None) -> int:
    from _args import Parser, device, integer  # (this folder; the module itself is imported as a plugin too)

    parser = Parser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--steps", type=integer(1, 10_000), default=48, help="steps of each run")
    parser.add_argument("--resolution", type=integer(24, 256), default=24, help="grid cells across the 1 m box")
    parser.add_argument("--device", type=device, default="cpu", help="cpu, or cuda[:N] where there is one")
    args = parser.parse_args(argv)
    differ = compare(args.steps, args.resolution, args.device)
    for name, fields in differ.items():
        print(f"{name}: {'the same bits as the built-in' if not fields else 'differs in ' + ', '.join(fields)} "
              f"after {args.steps} steps")
    return 1 if any(differ.values()) else 0


if __name__ == "__main__":
    wp.config.log_level = wp.LOG_ERROR  # no start-up banner or module-load lines
    raise SystemExit(main())
