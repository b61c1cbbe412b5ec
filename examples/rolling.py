"""A solid disk (2D) or sphere (3D) rolling from rest down a plane, on a
rigid collider or on an anchored elastic slab, with Coulomb friction,
against the closed form, at one or several resolutions.

    python examples/rolling.py [--dim 2] [--on collider] [--scheme empm] [--resolutions 32,48,64]
        [--angle 20] [--friction 0.5] [--duration 0.4] [--integrator explicit] [--kernel quadratic]
        [--device cpu] [--boundary separate] [--stiffness 0.5] [--damping 0] [--dt 0]

The body (radius R = 0.1 m, fixed-corotated E = 2e5 Pa, nu = 0.3,
rho = 1000 kg/m^3) starts at rest, touching the plane y = 0.25 m, in a box
1 m long; gravity (g = 9.81 m/s^2) is tilted by ``--angle`` theta towards
+x, so that the plane is inclined at theta in its own frame. The plane is
a half-space collider (``--on collider``, friction mu, the body free to
leave it) or the top of a slab 0.1 m thick (``--on body``, E = 2e6 Pa,
0.8 m long, its bottom strip held still, friction mu between the bodies, contact
normal "stiffer", fill 1). The collider acts on the grid (``--boundary
separate``) or through springs on the particles that touch it (``elastic``,
``--stiffness``, with a normal dashpot ``--damping``, mpm.elastic_contact);
on the slab, ``elastic`` makes the bodies meet through springs on their
particles too (``contact="elastic"``, mpm.body_springs) instead of the
grid's contact. Rolling without slip, a solid disk accelerates at (2/3) g
sin theta and a sphere at (5/7) g sin theta while mu is above (1/3) tan
theta and (2/7) tan theta (mpm.inclines.rolling).

Per resolution (cells across 1 m) it prints the acceleration (twice the
t^2 coefficient of a parabola fitted to the centre of mass along the plane
from SETTLE to the end), its error against the closed form, the slip over
the same span (the integral of v + omega x R at the contact point; the
body starts without its weight on the plane and slips while the normal
load builds up) in cells, and the
centre's mean height above R over the run's second half (the sink, in
cells: a negative value is the body's flattening plus any penetration)
beside the elastic flattening under its weight by Hertz (mpm.hertz);
with several resolutions, the observed order of the error between
neighbours, log(e_i / e_j) / log(h_i / h_j). A bad argument ends it with one
line (``error: --option: value; accepted: ...``) and exit code 2.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_ERROR  # no start-up banner or module-load lines

import mpm  # noqa: E402
from mpm.hertz import contact_modulus, cylinder_approach, sphere_approach  # noqa: E402
from mpm.inclines import rolling  # noqa: E402
from _args import Parser, bounded, choice, device, integer_list  # noqa: E402 (this folder)

G = 9.81  # [m/s^2]
R = 0.1  # the body's radius [m]
TOP = 0.25  # the plane's height [m]
SETTLE = 0.1  # the fit starts here [s]: the body starts without its weight on the plane
SAMPLE = 0.0025  # the body's motion is sampled every this many seconds [s]
PLANES = ("collider", "body")
BOUNDARIES = ("separate", "elastic")  # the collider's: the grid rule, or springs on the particles


def rigid_motion(x: np.ndarray, v: np.ndarray, m: np.ndarray):
    """The centre of mass [m], its velocity [m/s] and the angular velocity
    [rad/s] (the z component in 2D, a vector in 3D) of particles at ``x``
    with velocities ``v`` and masses ``m``: omega = I^-1 L about the centre."""
    M = m.sum()
    c, u = m @ x / M, m @ v / M
    r, w = x - c, v - u
    if x.shape[1] == 2:
        L = np.sum(m * (r[:, 0] * w[:, 1] - r[:, 1] * w[:, 0]))
        return c, u, L / np.sum(m * (r ** 2).sum(axis=1))
    inertia = np.einsum("p,pij->ij", m, (r ** 2).sum(axis=1)[:, None, None] * np.eye(3) - r[:, :, None] * r[:, None, :])
    return c, u, np.linalg.solve(inertia, m @ np.cross(r, w))


class Track(mpm.Observer):
    """The rolling body's centre [m], velocity [m/s] and spin (omega_z) [rad/s]
    every SAMPLE seconds."""

    def __init__(self, model: mpm.Model, body: int):
        self.start, self.count = model.body_ranges[body]
        self.m = model.mass.numpy()[self.start:self.start + self.count].astype(np.float64)
        self.t, self.c, self.v, self.w = [], [], [], []

    def wants(self, driver):
        return math.inf, (len(self.t) + 1) * SAMPLE

    def on_step(self, driver, report):
        if driver.time + 1e-12 < (len(self.t) + 1) * SAMPLE:
            return
        part = slice(self.start, self.start + self.count)
        c, u, w = rigid_motion(driver.state.x.numpy()[part].astype(np.float64),
                               driver.state.v.numpy()[part].astype(np.float64), self.m)
        self.t.append(driver.time)
        self.c.append(c)
        self.v.append(u)
        self.w.append(float(np.atleast_1d(w)[-1]))


@dataclass
class Rolled:
    """One run's figures."""

    resolution: int
    acceleration: float  # [m/s^2]
    expected: float  # [m/s^2]
    slip: float  # [m] along the plane at the contact point
    sink: float  # [m] the centre's mean height over TOP + R in the second half (negative: below)
    flattening: float  # [m] the elastic (Hertz) approach under the body's weight normal to the plane
    steps: int
    seconds: float  # wall-clock [s], compilation included

    @property
    def error(self) -> float:
        return self.acceleration / self.expected - 1.0


def scene(dim: int = 2, on: str = "collider", resolution: int = 64, angle: float = 20.0,
          friction: float = 0.5, boundary: str = "separate", stiffness: float = 0.5,
          damping: float = mpm.Collider.damping) -> mpm.Scene:
    """The scene of the module docstring."""
    th = math.radians(angle)
    depth = (0.25,) if dim == 3 else ()  # the 3D box is 0.5 m deep; the body in its middle
    ball = mpm.Body(mpm.Sphere((0.2, TOP + R) + depth, R), mpm.FixedCorotated(E=2.0e5, nu=0.3), name="ball")
    bodies, colliders, regions = [ball], [], []
    if on == "collider":
        colliders = [mpm.Collider.half_space((0.5, TOP) + depth, (0.0, 1.0) + (0.0,) * (dim - 2),
                                             boundary=boundary, friction=friction, stiffness=stiffness,
                                             damping=damping,
                                             name="plane")]
    else:
        across = (0.13,) if dim == 3 else ()
        slab = mpm.Body(mpm.Box((0.5, TOP - 0.05) + depth, (0.4, 0.05) + across),
                        mpm.FixedCorotated(E=2.0e6, nu=0.3), name="slab")
        bodies = [slab, ball]
        held = mpm.Box((0.5, TOP - 0.09) + depth, (0.4, 0.011) + across)
        regions = [mpm.KinematicRegion(body=0, select=held, velocity=(0.0,) * dim)]
    return mpm.Scene(
        dim=dim, domain=(1.0, 0.625) + ((0.5,) if dim == 3 else ()), resolution=resolution,
        ppc=4 if dim == 2 else 8, bodies=bodies, colliders=colliders, regions=regions,
        gravity=(G * math.sin(th), -G * math.cos(th)) + (0.0,) * (dim - 2), walls=("slip",) * (2 * dim),
        contact=("frictionless" if on == "collider" else ("elastic" if boundary == "elastic" else "friction")),
        contact_stiffness=stiffness, contact_friction=friction if on == "body" else 0.0,
        contact_normal="stiffer", contact_share=0.1, contact_fill=1.0)


def roll(dim: int = 2, on: str = "collider", scheme: str = "empm", resolution: int = 64, angle: float = 20.0,
         friction: float = 0.5, duration: float = 0.4, integrator: str = "explicit", kernel: str = "quadratic",
         device: str = "cpu", boundary: str = "separate", stiffness: float = 0.5, dt: float = 0.0,
         damping: float = mpm.Collider.damping) -> Rolled:
    """Run the scene for ``duration`` [s] (steps of ``dt`` [s]; 0: the step
    rule's) and measure it (module docstring)."""
    wall = time.perf_counter()
    model, state = mpm.build(scene(dim, on, resolution, angle, friction, boundary, stiffness, damping),
                             mpm.KERNELS[kernel], "float32", device)
    solver = mpm.Solver(model, mpm.SCHEMES[scheme](), mpm.SolverOptions(integrator=mpm.INTEGRATORS[integrator]()))
    track = Track(model, len(model.body_ranges) - 1)
    policy = mpm.StepPolicy(duration=duration, dt=dt) if dt else mpm.StepPolicy(duration=duration)
    driver = mpm.Driver(solver, state, policy, observers=[track])
    if driver.run().status != "completed":
        raise RuntimeError(f"the run stopped: {driver.outcome.reason}")
    t, c, v, w = np.array(track.t), np.array(track.c), np.array(track.v), np.array(track.w)
    fit = t >= SETTLE
    a = 2.0 * np.polyfit(t[fit], c[fit, 0], 2)[0]
    rate = v[:, 0] + w * R  # the contact point's velocity along the plane (omega_z < 0 rolling to +x)
    slip = float(np.sum(0.5 * (rate[1:] + rate[:-1])[fit[1:]] * np.diff(t)[fit[1:]]))
    sink = float(np.mean(c[t >= t[-1] / 2, 1]) - (TOP + R))
    return Rolled(resolution, float(a), rolling(angle, G, friction, "disk" if dim == 2 else "sphere"), slip, sink,
                  flattening(dim, on, angle), driver.step, time.perf_counter() - wall)


def flattening(dim: int, on: str, angle: float) -> float:
    """The approach [m] of the body's centre to the plane under its weight's
    normal part M g cos theta, by Hertz (mpm.hertz: the sphere's, or the
    cylinder's per unit length), against the rigid collider or the slab
    (their combined modulus)."""
    Es = contact_modulus(2.0e5, 0.3) if on == "collider" else contact_modulus(2.0e5, 0.3, 2.0e6, 0.3)
    M = 1000.0 * (math.pi * R * R if dim == 2 else 4.0 / 3.0 * math.pi * R ** 3)  # [kg/m in 2D, kg]
    N = M * G * math.cos(math.radians(angle))
    return -(cylinder_approach(N, R, Es) if dim == 2 else sphere_approach(N, R, Es))


def orders(runs: list[Rolled]) -> list[float]:
    """The observed order of the acceleration's error between neighbouring
    resolutions: log(|e_i| / |e_j|) / log(h_i / h_j), h = 1 / resolution."""
    return [math.log(abs(a.error) / abs(b.error)) / math.log(b.resolution / a.resolution)
            if a.error and b.error else math.nan for a, b in zip(runs, runs[1:])]


def main(argv=None) -> int:
    parser = Parser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--dim", type=choice(("2", "3")), default="2", help="2 (a disk) or 3 (a sphere)")
    parser.add_argument("--on", type=choice(PLANES), default="collider", help=", ".join(PLANES))
    parser.add_argument("--scheme", type=choice(mpm.SCHEMES), default="empm", help=", ".join(mpm.SCHEMES))
    parser.add_argument("--resolutions", type=integer_list(16, 256), default=[32, 48, 64],
                        help="comma-separated cells across 1 m")
    parser.add_argument("--angle", type=bounded(1.0, 60.0, "deg"), default=20.0, help="the incline [deg]")
    parser.add_argument("--friction", type=bounded(0.0, 2.0, "-"), default=0.5, help="Coulomb mu")
    parser.add_argument("--duration", type=bounded(0.2, 2.0, "s"), default=0.4, help="simulated time [s]")
    parser.add_argument("--integrator", type=choice(mpm.INTEGRATORS), default="explicit",
                        help=", ".join(mpm.INTEGRATORS))
    parser.add_argument("--kernel", type=choice(mpm.KERNELS), default="quadratic", help=", ".join(mpm.KERNELS))
    parser.add_argument("--device", type=device, default="cpu", help="cpu, or cuda[:N] where there is one")
    parser.add_argument("--boundary", type=choice(BOUNDARIES), default="separate",
                        help="the collider's: separate (the grid rule) or elastic (springs on the particles)")
    parser.add_argument("--stiffness", type=bounded(0.01, 4.0, "-"), default=0.5,
                        help="an elastic collider's springs, times the body's P-wave modulus")
    parser.add_argument("--damping", type=bounded(0.0, 1.0, "-"), default=mpm.Collider.damping,
                        help="an elastic collider's normal dashpot, a fraction of a particle's critical damping")
    parser.add_argument("--dt", type=bounded(0.0, 0.01, "s"), default=0.0, help="a fixed step [s]; 0: the step rule")
    args = parser.parse_args(argv)
    shape = "disk" if args.dim == "2" else "sphere"
    plane = "a slab" if args.on == "body" else ("an elastic collider" if args.boundary == "elastic" else "a collider")
    print(f"a {shape} rolling on {plane}, {args.scheme}, {args.integrator}, {args.kernel}, "
          f"theta {args.angle:g} deg, mu {args.friction:g}, {args.duration:g} s")
    print(f"{'cells':>5} {'a [m/s^2]':>10} {'closed':>8} {'error':>8} {'slip [cells]':>12} "
          f"{'sink [cells]':>12} {'elastic':>8} {'steps':>6} {'wall [s]':>8}")
    runs = []
    for res in args.resolutions:
        r = roll(int(args.dim), args.on, args.scheme, res, args.angle, args.friction, args.duration,
                 args.integrator, args.kernel, args.device, args.boundary, args.stiffness, args.dt,
                 args.damping)
        runs.append(r)
        print(f"{res:>5} {r.acceleration:>10.4f} {r.expected:>8.4f} {100 * r.error:>+7.2f}% "
              f"{r.slip * res:>12.3f} {r.sink * res:>12.3f} {r.flattening * res:>8.3f} {r.steps:>6} {r.seconds:>8.1f}")
    if len(runs) > 1:
        print("observed order of the error: " + ", ".join(
            f"{a.resolution}->{b.resolution}: {p:.2f}" for a, b, p in zip(runs, runs[1:], orders(runs))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
