"""A rigid block sliding or held, or a rigid disk (3D: sphere) rolling, on
an anchored elastic slab down a plane tilted by gravity, coupled through
Newton, against the closed forms, at one or several resolutions (2D or 3D).

    python examples/rigid_incline.py [--case slide] [--resolutions 32,64] [--angle 30] [--friction 0.3]
        [--gap 0.005] [--dim 2] [--duration 0.4] [--scheme empm] [--kernel quadratic]
        [--integrator explicit] [--static] [--device cpu] [--boundary separate] [--damping 0]

The slab (0.8 x 0.1 m, fixed-corotated E = 2e6 Pa, nu = 0.3, rho = 1000
kg/m^3, its bottom strip held still by a kinematic region, as in
examples/rolling.py) has its top at y = 0.25 m in a box 1 m long; gravity
(g = 9.81 m/s^2) is tilted by ``--angle`` theta towards +x. Onto it a
rigid body (mpm.RigidBody, density 1000 kg/m^3, advanced by Newton) is
dropped from ``--gap`` above (default DROP = 5 mm; 0: flush with the
slab's top, which lies on a grid line, where a block once stayed caught,
mpm.collider_device.make_edge): a box
0.1 x 0.05 m (``--case slide`` or ``--case hold``) or a disk of radius
0.05 m (``--case roll``), its boundary "separate" (``--boundary elastic``:
springs on the slab's particles, with the normal dashpot ``--damping``,
mpm.elastic_contact) with Coulomb friction mu against the material. Closed forms (mpm.inclines): a block slides at
g (sin theta - mu cos theta) and is held where tan theta <= mu; a solid
disk rolls without slip at (2/3) g sin theta while mu >= (1/3) tan theta.
Defaults per case: slide 30 deg, mu 0.3; hold 20 deg, mu 0.5; roll 20 deg,
mu 0.5.

``--dim 3``: the same, cut down to what two CPU cores run: the domain
LX3 = 0.5 m long, 0.375 m high and 0.25 m deep (z), the slab 0.36 x 0.1 x
0.12 m with its top at y = TOP3 = 0.2 m, the body starting 0.12 m from its
end, a box 0.1 x 0.05 x 0.1 m or a sphere of radius 0.05 m, which rolls at
(5/7) g sin theta while mu >= (2/7) tan theta; 8 particles per cell. The
resolutions are still cells across 1 m (the grid's spacing is the 2D
one's at the same number: 64 is 32 cells along the 0.5 m), multiples of 8
(the domain a whole number of cells along each axis).

Per resolution (cells across 1 m) it prints the acceleration along the
plane read from the rigid body's own Newton state (twice the t^2
coefficient of a parabola fitted to its centre's x from SETTLE to the end),
its error against the closed form (for a held block: the travel over the
same span, in cells), the slip of the disk's contact point (the integral of
v + omega x R over the span, in cells), the steps and the wall-clock time
(``--integrator implicit``: also the Newton iterations and solves per step;
the body's velocity is held during each solve, mpm.rigid_coupling).
``--static`` makes the body a static collider where it starts (no rigid
body; nothing to measure but the cost, the baseline of the coupling's).
A bad argument ends it with one line (``error: --option: value; accepted:
...``) and exit code 2.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_ERROR  # no start-up banner or module-load lines

import mpm  # noqa: E402
from mpm.colliders import Collider  # noqa: E402
from mpm.inclines import rolling, sliding  # noqa: E402
from _args import Parser, bounded, choice, device, integer_list  # noqa: E402 (this folder)

G = 9.81  # [m/s^2]
TOP = 0.25  # the slab's top [m]
HALF = (0.05, 0.025)  # the block's half sizes [m]
R = 0.05  # the disk's radius [m]
DROP = 0.005  # the body starts this far above the slab [m] (see the module docstring)
LX3, TOP3 = 0.5, 0.2  # 3D: the domain's length and the slab's top [m]
SETTLE = 0.1  # the fit starts here [s]: the body settles onto the slab first
SAMPLE = 0.0025  # the body's state is sampled every this many seconds [s]
CASES = {"slide": (30.0, 0.3), "hold": (20.0, 0.5), "roll": (20.0, 0.5)}
"""case: (default angle [deg], default mu)"""


class Track(mpm.Observer):
    """The rigid body's centre [m], velocity [m/s] and spin omega_z [rad/s]
    from Newton's state (the solver's rigid coupler) every SAMPLE seconds;
    under the implicit integrator, the Newton iterations and solves summed."""

    def __init__(self):
        self.t, self.c, self.v, self.w = [], [], [], []
        self.newton = self.solves = 0

    def wants(self, driver):
        return math.inf, (len(self.t) + 1) * SAMPLE

    def on_step(self, driver, report):
        if report.newton is not None:
            self.newton += report.newton.newton
            self.solves += 1 + report.newton.rounds
        if driver.time + 1e-12 < (len(self.t) + 1) * SAMPLE:
            return
        rigid = driver.solver.conditions.rigid
        if rigid is None:  # (--static: no body to follow)
            return
        p = rigid.poses()
        self.t.append(driver.time)
        self.c.append(p["position"][0][:2])
        self.v.append(p["velocity"][0][:2])
        self.w.append(float(p["angular_velocity"][0][2]))


@dataclass
class Run:
    """One run's figures."""

    case: str
    resolution: int
    acceleration: float  # [m/s^2]
    expected: float  # [m/s^2]
    travel: float  # [m] along the plane from SETTLE to the end
    slip: float  # [m] the disk's contact point along the plane over the same span (block: the travel)
    steps: int
    seconds: float  # wall-clock [s], compilation included
    newton: float = 0.0  # implicit: Newton iterations per step
    solves: float = 0.0  # implicit: solves per step (1 + the rounds of friction and one-sided constraints)

    @property
    def error(self) -> float:
        return self.acceleration / self.expected - 1.0 if self.expected else math.nan


def scene(case: str = "slide", resolution: int = 64, angle: float = 30.0, friction: float = 0.3,
          static: bool = False, gap: float = DROP, dim: int = 2, boundary: str = "separate",
          damping: float = Collider.damping) -> mpm.Scene:
    """The scene of the module docstring, the body ``gap`` [m] above the
    slab, ``resolution`` cells across 1 m (``static``: the body a static
    collider; ``boundary`` its, "separate" or "elastic", with the springs'
    normal dashpot ``damping``: mpm.elastic_contact)."""
    th = math.radians(angle)
    keys = dict(boundary=boundary, friction=friction, damping=damping)
    if dim == 3:
        z = 0.125  # the middle of the depth [m]
        if case == "roll":
            shape = Collider.sphere((0.13, TOP3 + gap + R, z), R, **keys)
        else:
            shape = Collider.box((0.13, TOP3 + gap + HALF[1], z), (HALF[0], HALF[1], HALF[0]), **keys)
        slab = mpm.Body(mpm.Box((0.25, TOP3 - 0.05, z), (0.18, 0.05, 0.06)), mpm.FixedCorotated(E=2.0e6, nu=0.3),
                        name="slab")
        held = mpm.Box((0.25, TOP3 - 0.09, z), (0.18, 0.011, 0.06))
        return mpm.Scene(
            dim=3, domain=(LX3, 0.375, 0.25), resolution=round(resolution * LX3), ppc=8, bodies=[slab],
            regions=[mpm.KinematicRegion(body=0, select=held, velocity=(0.0, 0.0, 0.0))],
            gravity=(G * math.sin(th), -G * math.cos(th), 0.0), walls=("slip",) * 6,
            colliders=[shape] if static else [],
            rigid_bodies=[] if static else [mpm.RigidBody(shape, density=1000.0, name=case)])
    if case == "roll":
        shape = Collider.sphere((0.2, TOP + gap + R), R, **keys)
    else:
        shape = Collider.box((0.2, TOP + gap + HALF[1]), HALF, **keys)
    slab = mpm.Body(mpm.Box((0.5, TOP - 0.05), (0.4, 0.05)), mpm.FixedCorotated(E=2.0e6, nu=0.3), name="slab")
    held = mpm.Box((0.5, TOP - 0.09), (0.4, 0.011))
    return mpm.Scene(
        dim=2, domain=(1.0, 0.625), resolution=resolution, ppc=4, bodies=[slab],
        regions=[mpm.KinematicRegion(body=0, select=held, velocity=(0.0, 0.0))],
        gravity=(G * math.sin(th), -G * math.cos(th)), walls=("slip",) * 4,
        colliders=[shape] if static else [],
        rigid_bodies=[] if static else [mpm.RigidBody(shape, density=1000.0, name=case)])


def run(case: str = "slide", resolution: int = 64, angle: float = 30.0, friction: float = 0.3,
        duration: float = 0.4, scheme: str = "empm", kernel: str = "quadratic", device: str = "cpu",
        integrator: str = "explicit", static: bool = False, gap: float = DROP, dim: int = 2,
        boundary: str = "separate", damping: float = Collider.damping) -> Run:
    """Run the scene for ``duration`` [s] and measure it (module docstring;
    ``static``: the cost only, the figures of the motion nan)."""
    wall = time.perf_counter()
    model, state = mpm.build(scene(case, resolution, angle, friction, static, gap, dim, boundary, damping),
                             mpm.KERNELS[kernel], "float32", device)
    solver = mpm.Solver(model, mpm.SCHEMES[scheme](), mpm.SolverOptions(integrator=mpm.INTEGRATORS[integrator]()))
    track = Track()
    driver = mpm.Driver(solver, state, mpm.StepPolicy(duration=duration), observers=[track])
    if driver.run().status != "completed":
        raise RuntimeError(f"the run stopped: {driver.outcome.reason}")
    steps = driver.step
    if static:
        return Run(case, resolution, math.nan, math.nan, math.nan, math.nan, steps, time.perf_counter() - wall,
                   track.newton / steps, track.solves / steps)
    t, c, v, w = np.array(track.t), np.array(track.c), np.array(track.v), np.array(track.w)
    fit = t >= SETTLE
    a = 2.0 * np.polyfit(t[fit], c[fit, 0], 2)[0]
    travel = float(c[fit, 0][-1] - c[fit, 0][0])
    rate = v[:, 0] + (w * R if case == "roll" else 0.0)  # the contact point's velocity along the plane
    slip = float(np.sum(0.5 * (rate[1:] + rate[:-1])[fit[1:]] * np.diff(t)[fit[1:]]))
    expected = (rolling(angle, G, friction, "disk" if dim == 2 else "sphere") if case == "roll"
                else sliding(angle, G, friction))
    return Run(case, resolution, float(a), expected, travel, slip, steps, time.perf_counter() - wall,
               track.newton / steps, track.solves / steps)


def main(argv=None) -> int:
    parser = Parser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--case", type=choice(tuple(CASES)), default="slide", help=", ".join(CASES))
    parser.add_argument("--resolutions", type=integer_list(16, 256), default=[32, 64],
                        help="comma-separated cells across 1 m")
    parser.add_argument("--angle", type=bounded(1.0, 60.0, "deg"), default=None,
                        help="the incline [deg] (default: the case's)")
    parser.add_argument("--friction", type=bounded(0.0, 2.0, "-"), default=None,
                        help="Coulomb mu (default: the case's)")
    parser.add_argument("--duration", type=bounded(0.2, 2.0, "s"), default=0.4, help="simulated time [s]")
    parser.add_argument("--scheme", type=choice(mpm.SCHEMES), default="empm", help=", ".join(mpm.SCHEMES))
    parser.add_argument("--kernel", type=choice(mpm.KERNELS), default="quadratic", help=", ".join(mpm.KERNELS))
    parser.add_argument("--integrator", type=choice(mpm.INTEGRATORS), default="explicit",
                        help=", ".join(mpm.INTEGRATORS))
    parser.add_argument("--static", action="store_true",
                        help="the body a static collider where it starts: the cost's baseline")
    parser.add_argument("--gap", type=bounded(0.0, 0.05, "m"), default=DROP,
                        help="the body's start above the slab [m] (0: flush)")
    parser.add_argument("--dim", type=choice(("2", "3")), default="2", help="2 or 3")
    parser.add_argument("--device", type=device, default="cpu", help="cpu, or cuda[:N] where there is one")
    parser.add_argument("--boundary", type=choice(("separate", "elastic")), default="separate",
                        help="the body's: separate (the grid rule) or elastic (springs on the slab's particles)")
    parser.add_argument("--damping", type=bounded(0.0, 1.0, "-"), default=Collider.damping,
                        help="an elastic body's normal dashpot, a fraction of a particle's critical damping")
    args = parser.parse_args(argv)
    dim = int(args.dim)
    odd = [r for r in args.resolutions if dim == 3 and r % 8]
    if odd:
        parser.error(f"--resolutions: {odd[0]}; accepted in 3D: multiples of 8 (cells across 1 m; "
                     "the domain 0.5 x 0.375 x 0.25 m)")
    angle = CASES[args.case][0] if args.angle is None else args.angle
    mu = CASES[args.case][1] if args.friction is None else args.friction
    body = ("disk" if dim == 2 else "sphere") if args.case == "roll" else "block"
    body = f"static {body} collider" if args.static else f"rigid {body}"
    print(f"a {body} ({args.case}, {args.boundary}) on an elastic slab, {args.scheme}, {args.kernel}, "
          f"{args.integrator}, theta {angle:g} deg, mu {mu:g}, gap {args.gap:g} m, {args.duration:g} s, {dim}D")
    print(f"{'cells':>5} {'a [m/s^2]':>10} {'closed':>8} {'error':>8} {'travel [cells]':>14} "
          f"{'slip [cells]':>12} {'steps':>6} {'wall [s]':>8}"
          + (f" {'newton/step':>11} {'solves/step':>11}" if args.integrator == "implicit" else ""))
    for res in args.resolutions:
        r = run(args.case, res, angle, mu, args.duration, args.scheme, args.kernel, args.device, args.integrator,
                args.static, args.gap, dim, args.boundary, args.damping)
        error = f"{100 * r.error:>+7.2f}%" if r.expected and not args.static else f"{'-':>8}"
        motion = (f"{'-':>10} {'-':>8} {error} {'-':>14} {'-':>12}" if args.static else
                  f"{r.acceleration:>10.4f} {r.expected:>8.4f} {error} {r.travel * res:>14.3f} {r.slip * res:>12.3f}")
        print(f"{res:>5} {motion} {r.steps:>6} {r.seconds:>8.1f}"
              + (f" {r.newton:>11.2f} {r.solves:>11.2f}" if args.integrator == "implicit" else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
