"""A free elastic block spinning about its centre: the angular momentum it
keeps under the explicit and the implicit integrator, against the step.

    python examples/spinning_block.py [--integrator implicit] [--dts 4e-3,2e-3,1e-3] [--duration 0.15]
        [--omega 5] [--dim 2] [--resolution 32] [--scheme empm] [--kernel quadratic] [--transfer mls]
        [--newton-tol 1e-4] [--device cpu]

The block (0.24 m wide, fixed-corotated E = 2e5 Pa, nu = 0.3,
rho = 1000 kg/m^3, float64) starts at the centre of a 1 m box spinning at
``--omega`` w about z (v = w x (x - c), C its gradient), unstressed, with no
gravity and no wall reached. Per step size it prints the fraction of its
angular momentum about the origin lost over ``--duration`` T (APIC's about
the centre of mass plus c x P), beside backward Euler's estimate w^2 T dt (a
steady spin loses (w dt)^2 of it a step: mpm.integrators), their ratio,
the momentum |P| over M w a (a the half-width), the relative change of the
kinetic plus elastic energy, the Newton iterations, and, under the implicit
integrator, the largest gap over the steps between a step's change of L
and dt/G sum_i m_i v~_i x v*_i (backward Euler's, v* the nodes' velocities
from P2G, v~ the solve's), over L(0); with several steps, the observed
order of the loss, log(l_i / l_j) / log(dt_i / dt_j). A bad argument ends
it with one line (``error: --option: value; accepted: ...``) and exit code 2.
"""

from __future__ import annotations

import math
import time

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_ERROR  # no start-up banner or module-load lines

import mpm  # noqa: E402
from mpm.integrators import Explicit, Implicit  # noqa: E402
from _args import Parser, bounded, bounded_list, choice, device, integer  # noqa: E402 (this folder)

HALF = 0.12  # the block's half-width [m]
TRANSFERS = ("mls", "apic")  # the affine transfers, which keep angular momentum (PIC does not)


def spin(dim: int, scheme: str, kernel: str, transfer: str, resolution: int, omega: float, duration: float,
         dt: float, integrator, device: str) -> dict:
    """One run; the figures printed per step size."""
    c = (0.5,) * dim
    body = mpm.Body(mpm.Box(c, (HALF,) * dim), mpm.FixedCorotated(E=2e5, nu=0.3, rho=1000.0))
    scene = mpm.Scene(dim=dim, domain=(1.0,) * dim, resolution=resolution, ppc=4 if dim == 2 else 8,
                      gravity=(0.0,) * dim, walls=("open",) * (2 * dim), bodies=[body])
    model, state = mpm.build(scene, mpm.KERNELS[kernel], "float64", device)
    solver = mpm.Solver(model, mpm.SCHEMES[scheme](), mpm.SolverOptions(transfer=transfer, integrator=integrator))
    solver.prepare(state)
    W = np.zeros((dim, dim))
    W[0, 1], W[1, 0] = -omega, omega
    state.v.assign((state.x.numpy() - np.asarray(c)) @ W.T)
    state.C.assign(np.broadcast_to(W, (model.n_particles, dim, dim)).copy())
    names, axes = solver.diagnostics.names, "xyz"[:dim]

    def measure():
        d = solver.measure(state)
        cm, P = (np.array([d[names.index(f"{k}_{a}")] for a in axes]) for k in ("center_of_mass", "momentum"))
        L = d[names.index("angular_momentum" if dim == 2 else "angular_momentum_z")] + cm[0] * P[1] - cm[1] * P[0]
        return L, P, d[names.index("kinetic_energy")] + d[names.index("elastic_energy")], d[names.index("mass")]

    step_loss = {"dL": 0.0}
    if solver.implicit is not None:  # backward Euler's change of L in each step, from the solve's nodes
        solve, G = solver.implicit.solve, model.kernel.n_grids

        def solve_and_record(st, dtS):
            rep = solve(st, dtS)
            n = solver.layout.n_nodes
            m, v_star, v = solver.grid.m.numpy()[:n], solver.implicit.v_star.numpy()[:n], solver.grid.v.numpy()[:n]
            step_loss["dL"] = float(dtS) * float(np.sum(m * (v[:, 0] * v_star[:, 1] - v[:, 1] * v_star[:, 0]))) / G
            return rep

        solver.implicit.solve = solve_and_record
    L0, _, E0, M = measure()
    L, gap, newton, start = L0, 0.0, 0, time.perf_counter()
    for _ in range(int(round(duration / dt))):
        report = solver.advance(state, dt)
        if report.reason is not None:
            raise SystemExit(f"error: the step failed: {report.reason}")
        newton += report.newton.newton if report.newton is not None else 0
        L, before = measure()[0], L
        if solver.implicit is not None:
            gap = max(gap, abs(L - before - step_loss["dL"]) / abs(L0))
    L, P, E, _ = measure()
    return dict(loss=(L0 - L) / L0, P=float(np.linalg.norm(P)) / (M * abs(omega) * HALF), dE=(E - E0) / E0,
                gap=gap, newton=newton, seconds=time.perf_counter() - start)


def main(argv=None) -> int:
    parser = Parser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--integrator", type=choice(mpm.INTEGRATORS), default="implicit",
                        help=", ".join(mpm.INTEGRATORS))
    parser.add_argument("--dts", type=bounded_list(1e-5, 1e-2, "s"), default=[4e-3, 2e-3, 1e-3],
                        help="comma-separated step sizes [s]")
    parser.add_argument("--duration", type=bounded(0.01, 2.0, "s"), default=0.15, help="simulated time [s]")
    parser.add_argument("--omega", type=bounded(0.1, 50.0, "rad/s"), default=5.0, help="the spin [rad/s]")
    parser.add_argument("--dim", type=choice(("2", "3")), default="2", help="2 or 3")
    parser.add_argument("--resolution", type=integer(8, 128), default=32, help="cells across 1 m")
    parser.add_argument("--scheme", type=choice(mpm.SCHEMES), default="empm", help=", ".join(mpm.SCHEMES))
    parser.add_argument("--kernel", type=choice(mpm.KERNELS), default="quadratic", help=", ".join(mpm.KERNELS))
    parser.add_argument("--transfer", type=choice(TRANSFERS), default="mls", help=", ".join(TRANSFERS))
    parser.add_argument("--newton-tol", type=bounded(1e-12, 0.1, "-"), default=1e-4,
                        help="the implicit integrator's newton_tol [-]")
    parser.add_argument("--device", type=device, default="cpu", help="cpu, or cuda[:N] where there is one")
    args = parser.parse_args(argv)
    integrator = Implicit(newton_tol=args.newton_tol) if args.integrator == "implicit" else Explicit()
    tol = f", newton_tol {args.newton_tol:g}" if args.integrator == "implicit" else ""
    print(f"a block spinning at {args.omega:g} rad/s, {args.dim}D, {args.resolution} cells, {args.scheme}, "
          f"{args.kernel}, {args.transfer}, {args.integrator}{tol}, {args.duration:g} s, float64")
    print(f"{'dt [s]':>8} {'L lost':>11} {'w^2 T dt':>9} {'ratio':>6} {'|P|/Mwa':>9} {'dE/E':>10} "
          f"{'step gap/L0':>11} {'newton':>6} {'wall [s]':>8}")
    losses = []
    for dt in args.dts:
        r = spin(int(args.dim), args.scheme, args.kernel, args.transfer, args.resolution, args.omega,
                 args.duration, dt, integrator, args.device)
        estimate = args.omega**2 * args.duration * dt
        losses.append(r["loss"])
        gap = f"{r['gap']:>11.2e}" if args.integrator == "implicit" else f"{'-':>11}"
        print(f"{dt:>8.2g} {r['loss']:>+11.4e} {estimate:>9.3e} {r['loss'] / estimate:>6.3f} {r['P']:>9.1e} "
              f"{r['dE']:>+10.3e} {gap} {r['newton']:>6} {r['seconds']:>8.1f}")
    if len(losses) > 1:
        orders = [math.log(a / b) / math.log(p / q) if a > 0 and b > 0 and p != q else math.nan
                  for a, b, p, q in zip(losses, losses[1:], args.dts, args.dts[1:])]
        print("observed order of the loss: " + ", ".join(
            f"{p:g}->{q:g}: {o:.2f}" for p, q, o in zip(args.dts, args.dts[1:], orders)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
