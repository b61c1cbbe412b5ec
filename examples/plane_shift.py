"""A block sliding down, or held on, a rough collider plane whose surface
lies between two rows of grid nodes: its acceleration must not depend on
where the surface falls.

    python examples/plane_shift.py [--shifts 0,0.25,0.5] [--scheme empm] [--resolution 64]
        [--slide 30,0.3] [--hold 20,0.5] [--duration 0.3] [--rule surface] [--ramp 0] [--device cpu]

The block (0.1 m square, fixed-corotated E = 2e5 Pa, nu = 0.3,
rho = 1000 kg/m^3) starts at rest on a half-space collider y >= 0.25 m +
shift dx (dx = 1 m / resolution; shift 0 puts the surface on a node row),
its bottom face on the surface. Gravity (9.81 m/s^2) is tilted by theta,
so that the plane is inclined at theta in its own frame, with Coulomb
friction mu. ``--slide theta,mu`` slides (tan theta > mu): a =
g (sin theta - mu cos theta); ``--hold theta,mu`` holds it (tan theta <=
mu): it must not move (mpm.inclines.sliding). Per shift it prints the
sliding block's acceleration (the slope of a line fitted to its mean
velocity from SETTLE on) and its error, the held block's travel along the
plane [cells], over the run and from LOADED on (it starts without its
weight on the plane and slips a little while the weight comes on), and
its mean height change [cells]; then the spread of the accelerations over
the shifts. The held block moves without slipping too, as its elastic
shear under the load along the plane: the same block on a sticky plane
(its base held) gives that travel, and the held block's slip is its travel
less the sticky one's. ``--ramp T`` applies the held block's weight as a
body force (mpm.Load) rising from 0 over T [s] instead of gravity at once
(its travel "from" then counts from T on; the sliding block keeps gravity
at once): a block
released with its full weight and no stress bounces on the plane, whose
reaction then falls below what friction needs to hold it, and it slips;
loaded slowly it has no reason to. ``--rule nodes`` runs the node rule of
earlier versions (Scene.boundary_rule), ``--rule elastic`` the plane as
an elastic collider (springs on the particles, mpm.elastic_contact). A bad argument ends it with one line
(``error: --option: value; accepted: ...``) and exit code 2.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_ERROR  # no start-up banner or module-load lines

import mpm  # noqa: E402
from mpm.inclines import sliding  # noqa: E402
from _args import Parser, bounded, bounded_list, choice, device, integer, positive  # noqa: E402 (this folder)

G = 9.81  # [m/s^2]
TOP = 0.25  # the plane's height at shift 0 [m]
HALF = 0.05  # the block's half side [m]
RHO = 1000.0  # the block's density [kg/m^3] (mpm.FixedCorotated's default)
SETTLE = 0.05  # the velocity fit starts here [s]
LOADED = 0.1  # the held block's weight is on the plane by then [s]
RULES = ("surface", "nodes", "elastic")  # Scene.boundary_rule, or the plane elastic (mpm.elastic_contact)


class Motion(mpm.Observer):
    """The block's mean position [m] and velocity [m/s] after every step."""

    def __init__(self, model: mpm.Model):
        self.m = model.mass.numpy().astype(np.float64)
        self.t, self.x, self.v = [], [], []

    def on_start(self, driver):
        self.on_step(driver, None)

    def on_step(self, driver, report):
        self.t.append(driver.time)
        self.x.append(self.m @ driver.state.x.numpy().astype(np.float64) / self.m.sum())
        self.v.append(self.m @ driver.state.v.numpy().astype(np.float64) / self.m.sum())

    def wants(self, driver):
        return driver.step + 1, math.inf


def run(shift: float, theta: float, mu: float | None, scheme: str = "empm", resolution: int = 64,
        duration: float = 0.3, rule: str = "surface", device: str = "cpu", ramp: float = 0.0) -> Motion:
    """The block on the plane shifted by ``shift`` cells, inclined at
    ``theta`` [deg] with friction ``mu`` (None: a sticky plane), for
    ``duration`` [s]; its weight at once, or rising over ``ramp`` [s]."""
    top = TOP + shift / resolution
    block = mpm.Body(mpm.Box((0.3, top + HALF), (HALF, HALF)), mpm.FixedCorotated(E=2.0e5, nu=0.3), name="block")
    boundary = "sticky" if mu is None else ("elastic" if rule == "elastic" else "separate")
    plane = mpm.Collider.half_space((0.5, top), (0.0, 1.0), boundary=boundary,
                                    friction=mu or 0.0, name="plane")
    th = math.radians(theta)
    g = (G * math.sin(th), -G * math.cos(th))
    weight = [mpm.Load.body_force(tuple(RHO * gi for gi in g), ramp=ramp, name="weight")] if ramp > 0.0 else []
    scene = mpm.Scene(dim=2, domain=(1.0, 0.5), resolution=resolution, ppc=4, bodies=[block], colliders=[plane],
                      gravity=(0.0, 0.0) if weight else g, loads=weight, walls=("slip",) * 4,
                      boundary_rule="surface" if rule == "elastic" else rule)
    model, state = mpm.build(scene, mpm.QUADRATIC, "float32", device)
    motion = Motion(model)
    driver = mpm.Driver(mpm.Solver(model, mpm.SCHEMES[scheme]()), state, mpm.StepPolicy(duration=duration),
                        observers=[motion])
    if driver.run().status != "completed":
        raise RuntimeError(f"the run stopped: {driver.outcome.reason}")
    return motion


def acceleration(motion: Motion) -> float:
    """The slope [m/s^2] of a line fitted to the mean velocity along the plane from SETTLE on."""
    t, v = np.array(motion.t), np.array(motion.v)[:, 0]
    return float(np.polyfit(t[t >= SETTLE], v[t >= SETTLE], 1)[0])


def main(argv=None) -> int:
    parser = Parser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--shifts", type=bounded_list(0.0, 1.0, "cells"), default=[0.0, 0.25, 0.5],
                        help="the plane's offsets from a node row [cells]")
    parser.add_argument("--scheme", type=choice(mpm.SCHEMES), default="empm", help=", ".join(mpm.SCHEMES))
    parser.add_argument("--resolution", type=integer(32, 256), default=64, help="cells across 1 m")
    parser.add_argument("--slide", type=bounded_list(0.0, 60.0, "deg, -", most=2), default=[30.0, 0.3],
                        help="theta [deg],mu of the sliding block")
    parser.add_argument("--hold", type=bounded_list(0.0, 60.0, "deg, -", most=2), default=[20.0, 0.5],
                        help="theta [deg],mu of the held block")
    parser.add_argument("--duration", type=positive("s"), default=0.3, help="simulated time [s]")
    parser.add_argument("--rule", type=choice(RULES), default="surface", help=", ".join(RULES))
    parser.add_argument("--ramp", type=bounded(0.0, 1.0, "s"), default=0.0,
                        help="the weight rises from 0 over this time [s] (0: gravity at once)")
    parser.add_argument("--device", type=device, default="cpu", help="cpu, or cuda[:N] where there is one")
    args = parser.parse_args(argv)
    for name in ("slide", "hold"):
        if len(getattr(args, name)) != 2:
            parser.error(f"--{name}: {','.join(map(str, getattr(args, name)))}; accepted: theta,mu")
    (ts, ms), (th, mh) = args.slide, args.hold
    if math.tan(math.radians(ts)) <= ms:
        parser.error(f"--slide: {ts:g},{ms:g}; accepted: theta,mu with tan(theta) > mu (it slides)")
    if math.tan(math.radians(th)) > mh:
        parser.error(f"--hold: {th:g},{mh:g}; accepted: theta,mu with tan(theta) <= mu (it holds)")
    closed = sliding(ts, G, ms, 0.0)
    weight = f"the weight rising over {args.ramp:g} s" if args.ramp > 0.0 else "the weight at once"
    print(f"{args.scheme}, {args.resolution} cells, rule {args.rule}: slide at {ts:g} deg, mu {ms:g} "
          f"(closed form {closed:.4f} m/s^2); hold at {th:g} deg, mu {mh:g}; {weight}")
    print(f"{'shift':>6} {'a [m/s^2]':>10} {'error':>8} {'held travel [cells]':>20} "
          f"{f'from {max(LOADED, args.ramp):g} s':>11} "
          f"{'held drop [cells]':>18} {'sticky travel':>14} {'slip':>8}")
    found = []
    for shift in args.shifts:
        same = dict(scheme=args.scheme, resolution=args.resolution, duration=args.duration, rule=args.rule,
                    device=args.device)
        a = acceleration(run(shift, ts, ms, **same))
        held, sticky = run(shift, th, mh, ramp=args.ramp, **same), run(shift, th, None, ramp=args.ramp, **same)
        x = np.array(held.x) * args.resolution
        late = x[np.array(held.t) >= max(LOADED, args.ramp), 0]
        shear = (sticky.x[-1][0] - sticky.x[0][0]) * args.resolution
        found.append(a)
        print(f"{shift:>6.3f} {a:>10.4f} {100 * (a / closed - 1):>+7.3f}% {x[-1, 0] - x[0, 0]:>20.4f} "
              f"{late[-1] - late[0]:>11.4f} {x[-1, 1] - x[0, 1]:>+18.4f} {shear:>14.4f} "
              f"{x[-1, 0] - x[0, 0] - shear:>8.4f}")
    print(f"spread of the accelerations over the shifts: {100 * (max(found) - min(found)) / closed:.3f} % "
          "of the closed form")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
