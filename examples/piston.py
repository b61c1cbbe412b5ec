"""A piston pushing water at 2 m/s: no particle may be inside the piston
after any step.

    python examples/piston.py [--speed 2] [--resolution 64] [--scheme empm] [--K 1e6] [--duration 0.15]
        [--rule surface] [--device cpu]

A tank 1 m long holds water (weakly compressible, rho = 1000 kg/m^3, bulk
modulus K: sound speed sqrt(K / rho) = 31.6 m/s at the default) 0.5 m long
and 0.25 m deep on its floor wall. A box collider as tall as the domain, its
face against the water's left side, moves right at ``--speed`` from the
start (slip: the water slides along its face) and pushes a wave up the
tank. After every step the script counts the particles inside the piston
(more than 1e-4 cell behind its moving face: a particle put back on the
face may round to a hair behind it in float32) and records the deepest
[cells]; it prints the largest count over the steps, the deepest
penetration, the step it happened at, and the piston's mean force on the
water. ``--rule nodes`` runs the node rule of earlier versions
(Scene.boundary_rule), without the keep-out step of the surface rule. A
bad argument ends it with one line (``error: --option: value; accepted:
...``) and exit code 2.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_ERROR  # no start-up banner or module-load lines

import mpm  # noqa: E402
from _args import Parser, bounded, choice, device, integer  # noqa: E402 (this folder)

G = 9.81  # [m/s^2]
FACE = 0.2  # the piston's face at t = 0 [m]
RULES = ("surface", "nodes", "elastic")  # Scene.boundary_rule, or the piston elastic (mpm.elastic_contact)
TOLERANCE = 1.0e-4  # a particle deeper than this [cells] is inside: above float32's rounding of the face (~1e-7 m)


class Inside(mpm.Observer):
    """After every step: how many particles lie behind the piston's face
    and how deep the deepest [m]."""

    def __init__(self, speed: float, grids: int, tolerance: float):
        self.speed, self.grids, self.tolerance = speed, grids, tolerance
        self.count, self.depth, self.impulse = [], [], 0.0

    def on_step(self, driver, report):
        """Count after the step; add the piston's impulse on the water [N s / m]."""
        face = FACE + self.speed * driver.time
        behind = face - driver.state.x.numpy()[:, 0]
        self.count.append(int((behind > self.tolerance).sum()))
        self.depth.append(float(max(behind.max(), 0.0)))
        self.impulse += float(report.collider_impulse[0][0]) / self.grids

    def wants(self, driver):
        return driver.step + 1, math.inf


def push(speed: float = 2.0, resolution: int = 64, scheme: str = "empm", K: float = 1.0e6, duration: float = 0.15,
         rule: str = "surface", device: str = "cpu") -> tuple[mpm.Driver, Inside]:
    """Run the scene of the module docstring; the driver and the counts."""
    dx = 1.0 / resolution
    floor = 3 * dx
    water = mpm.Body(mpm.Box((FACE + 0.25, floor + 0.125), (0.25, 0.125)), mpm.Fluid(K=K, rho=1000.0), name="water")
    piston = mpm.Collider.box((FACE - 0.1, 0.25), (0.1, 0.5), velocity=(speed, 0.0),
                              boundary="elastic" if rule == "elastic" else "slip", name="piston")
    scene = mpm.Scene(dim=2, domain=(1.0, 0.5), resolution=resolution, ppc=4, bodies=[water], colliders=[piston],
                      gravity=(0.0, -G), walls=("slip",) * 4, boundary_rule="surface" if rule == "elastic" else rule)
    model, state = mpm.build(scene, mpm.QUADRATIC, "float32", device)
    inside = Inside(speed, model.kernel.n_grids, TOLERANCE * dx)
    driver = mpm.Driver(mpm.Solver(model, mpm.SCHEMES[scheme]()), state, mpm.StepPolicy(duration=duration),
                        observers=[inside])
    driver.run()
    return driver, inside


def main(argv=None) -> int:
    parser = Parser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--speed", type=bounded(0.1, 5.0, "m/s"), default=2.0, help="the piston's speed [m/s]")
    parser.add_argument("--resolution", type=integer(32, 256), default=64, help="cells across 1 m")
    parser.add_argument("--scheme", type=choice(mpm.SCHEMES), default="empm", help=", ".join(mpm.SCHEMES))
    parser.add_argument("--K", type=bounded(1.0e4, 1.0e8, "Pa"), default=1.0e6, help="the water's bulk modulus [Pa]")
    parser.add_argument("--duration", type=bounded(0.01, 0.25, "s"), default=0.15, help="simulated time [s]")
    parser.add_argument("--rule", type=choice(RULES), default="surface", help=", ".join(RULES))
    parser.add_argument("--device", type=device, default="cpu", help="cpu, or cuda[:N] where there is one")
    args = parser.parse_args(argv)
    driver, inside = push(args.speed, args.resolution, args.scheme, args.K, args.duration, args.rule, args.device)
    out = driver.outcome
    worst = int(np.argmax(inside.depth))
    print(f"{out.status} after {driver.step} steps, t = {driver.time:.4g} s{': ' + out.reason if out.reason else ''}")
    print(f"rule {args.rule}, {args.scheme}, {args.resolution} cells, piston at {args.speed:g} m/s, K = {args.K:g} Pa")
    print(f"particles inside the piston after a step: at most {max(inside.count)} (steps with any: "
          f"{sum(c > 0 for c in inside.count)} of {len(inside.count)}); deepest "
          f"{inside.depth[worst] * args.resolution:.3f} cells at step {worst + 1}")
    print(f"the piston's mean force on the water {inside.impulse / max(driver.time, 1e-30):.4g} N/m")
    return 0 if out.status == "completed" else 1


if __name__ == "__main__":
    raise SystemExit(main())
