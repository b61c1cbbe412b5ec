"""A block resting under its weight on the domain's floor wall, on a
collider plane, or on a stiffer body: where its lowest particles settle
against where elasticity puts them.

    python examples/resting.py [--on wall,collider,body] [--schemes empm,tlmpm,aulmpm] [--resolution 32]
        [--shift 0] [--duration 0.5] [--rule surface] [--device cpu]

The block (0.2 m square, fixed-corotated E = 1e5 Pa, nu = 0.3,
rho = 1000 kg/m^3, g = 9.81 m/s^2) starts at rest with its bottom face on
the support: the floor wall's face (wall_cells = 3 cells above the domain's
bottom, on a node row), a frictionless half-space collider at
y = 0.25 m + shift dx, or the top of a slab ten times stiffer (E = 1e6 Pa,
0.1 m thick, its bottom strip held still, frictionless contact) at that
height. ``--rule elastic`` makes the collider elastic and the contact with
the slab ``elastic`` (springs on the particles: mpm.elastic_contact,
mpm.body_springs). Its lowest particles, a layer one sampling spacing s = dx / 2 thick,
start s / 2 above the support. On a frictionless rigid support the bottom
face stays on it and the sides are free (sigma_xx = 0, plane strain), so
the layer's centre comes down by the shortening of the material below it,
    (1 - nu^2) rho g (H s / 2 - s^2 / 8) / E,
H the block's height: a few thousandths of a cell. On the slab the support
itself comes down: the layer is measured from the slab's top particles
beneath the block (their mean height + s / 2), and the slab's own
shortening is left out of the elastic figure.

Per case it prints the lowest layer's mean height above the support over
the run's second half (the block rings after its sudden weight) less its
start, in cells, and the elastic change. A bad argument ends it with one
line (``error: --option: value; accepted: ...``) and exit code 2.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_ERROR  # no start-up banner or module-load lines

import mpm  # noqa: E402
from _args import Parser, bounded, choice, device, integer, positive  # noqa: E402 (this folder)

G = 9.81  # [m/s^2]
HALF = 0.1  # the block's half side [m]
E, NU, RHO = 1.0e5, 0.3, 1000.0  # the block's material
LEVEL = 0.25  # the collider's and the slab's top at shift 0 [m]
SUPPORTS = ("wall", "collider", "body")
RULES = ("surface", "nodes", "elastic")  # Scene.boundary_rule, or springs (mpm.elastic_contact, mpm.body_springs)


def csv_of(names):
    """Comma-separated names, each one of ``names`` (an argparse type)."""
    pick = choice(names)

    def check(text: str) -> list[str]:
        return [pick(part) for part in text.split(",")]
    return check


class Layer(mpm.Observer):
    """Every step, the lowest layer's mean height over the support [m]."""

    def __init__(self, lowest: np.ndarray, support):
        self.lowest, self.support = lowest, support
        self.t, self.h = [], []

    def on_start(self, driver):
        self.on_step(driver, None)

    def on_step(self, driver, report):
        x = driver.state.x.numpy()
        self.t.append(driver.time)
        self.h.append(float(x[self.lowest, 1].mean()) - self.support(x))

    def wants(self, driver):
        return driver.step + 1, math.inf


def rest(on: str = "wall", scheme: str = "empm", resolution: int = 32, shift: float = 0.0, duration: float = 0.5,
         rule: str = "surface", device: str = "cpu") -> tuple[float, float]:
    """The lowest layer's height change [m] (second-half mean less the
    start) and its elastic value [m]."""
    dx = 1.0 / resolution
    base = 3 * dx if on == "wall" else LEVEL + shift * dx
    block = mpm.Body(mpm.Box((0.5, base + HALF), (HALF, HALF)), mpm.FixedCorotated(E=E, nu=NU, rho=RHO), name="block")
    bodies, colliders, regions = [block], [], []
    if on == "collider":
        colliders = [mpm.Collider.half_space((0.5, base), (0.0, 1.0), boundary="elastic" if rule == "elastic" else
                                             "separate", name="plane")]
    elif on == "body":
        slab = mpm.Body(mpm.Box((0.5, base - 0.05), (0.3, 0.05)), mpm.FixedCorotated(E=10 * E, nu=NU, rho=RHO),
                        name="slab")
        bodies = [slab, block]
        regions = [mpm.KinematicRegion(body=0, select=mpm.Box((0.5, base - 0.1 + dx / 4), (0.3, dx / 4)),
                                       velocity=(0.0, 0.0))]
    scene = mpm.Scene(dim=2, domain=(1.0, 0.625), resolution=resolution, ppc=4, bodies=bodies, colliders=colliders,
                      regions=regions, gravity=(0.0, -G), walls=("slip",) * 4,
                      boundary_rule="surface" if rule == "elastic" else rule,
                      contact="elastic" if rule == "elastic" else "frictionless",
                      contact_normal="stiffer")
    model, state = mpm.build(scene, mpm.QUADRATIC, "float32", device)
    x0 = state.x.numpy().astype(np.float64)
    start, count = model.body_ranges[-1]
    ys = x0[start:start + count, 1]
    lowest = start + np.flatnonzero(ys < ys.min() + 1e-6 * dx)
    s = dx / 2  # the sampling spacing (ppc 4)
    if on == "body":
        s0, c0 = model.body_ranges[0]
        top = x0[s0:s0 + c0]
        under = s0 + np.flatnonzero((top[:, 1] > top[:, 1].max() - 1e-6 * dx)
                                    & (np.abs(top[:, 0] - 0.5) < HALF))

        def support(x):
            return float(x[under, 1].mean()) + s / 2
    else:
        def support(x):
            return base
    layer = Layer(lowest, support)
    driver = mpm.Driver(mpm.Solver(model, mpm.SCHEMES[scheme]()), state, mpm.StepPolicy(duration=duration),
                        observers=[layer])
    if driver.run().status != "completed":
        raise RuntimeError(f"the run stopped: {driver.outcome.reason}")
    t, h = np.array(layer.t), np.array(layer.h)
    elastic = -(1 - NU ** 2) * RHO * G * (2 * HALF * s / 2 - s * s / 8) / E
    return float(h[t >= duration / 2].mean() - h[0]), elastic


def main(argv=None) -> int:
    parser = Parser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--on", type=csv_of(SUPPORTS), default=list(SUPPORTS), help=",".join(SUPPORTS))
    parser.add_argument("--schemes", type=csv_of(mpm.SCHEMES), default=["empm", "tlmpm", "aulmpm"],
                        help=",".join(mpm.SCHEMES))
    parser.add_argument("--resolution", type=integer(16, 256), default=32, help="cells across 1 m")
    parser.add_argument("--shift", type=bounded(0.0, 1.0, "cells"), default=0.0,
                        help="the collider's and the slab's offset from a node row [cells]")
    parser.add_argument("--duration", type=positive("s"), default=0.5, help="simulated time [s]")
    parser.add_argument("--rule", type=choice(RULES), default="surface", help=", ".join(RULES))
    parser.add_argument("--device", type=device, default="cpu", help="cpu, or cuda[:N] where there is one")
    args = parser.parse_args(argv)
    res = args.resolution
    print(f"{res} cells, rule {args.rule}, shift {args.shift:g} cells: the lowest layer's height change [cells]")
    print(f"{'support':>9} {'scheme':>7} {'change':>9} {'elastic':>9}")
    for on in args.on:
        for scheme in args.schemes:
            change, elastic = rest(on, scheme, res, args.shift, args.duration, args.rule, args.device)
            print(f"{on:>9} {scheme:>7} {change * res:>+9.4f} {elastic * res:>+9.4f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
