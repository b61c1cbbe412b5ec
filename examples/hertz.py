"""Hertz contact: an elastic cylinder (2D, plane strain) or sphere (3D)
pressed slowly between two plates, its force against the plates'
approach, at one or several resolutions, against the closed forms
(mpm.hertz).

    python examples/hertz.py [--dim 2] [--on collider] [--scheme empm] [--resolutions 64,128]
        [--approach 8] [--duration 0.4] [--device cpu] [--boundary separate] [--sampling lattice]
        [--stiffness 0.5]

The body (radius R = 0.08 m, fixed-corotated E = 1e5 Pa, nu = 0.3,
rho = 1000 kg/m^3, no gravity) starts at rest in the middle of a box
0.25 m wide, touching two frictionless half-space colliders, one above and
one below it. The plates approach each other at a constant rate, each at
half of it, so that the body's centre stays put and no rigid motion rings:
``--approach`` millimetres in all over ``--duration`` seconds (about 30
times the time a compression wave takes across the body at the defaults). With
``--on body`` the lower plate is the top of an elastic slab 20 times
stiffer (E = 2e6 Pa, 0.02 m thick), pushed up by its bottom strip
(a kinematic region). The force is the upper collider's reaction
(StepReport.collider_impulse), averaged over each of ten windows; the
closed form gives the load at which the two contacts' approaches add up to
the plates' (the body against a rigid plate, and against the slab with
their combined modulus E*). Hertz's law holds while the contact is small
(the contact half-width at the default 8 mm is about 0.19 R in 2D): its
own error at the largest approach is a few per cent.

``--sampling shells`` places the body's particles on concentric layers
(mpm.sampling.sample_shells) instead of the grid's sub-lattice, whose top
layer is a flat facet that meets a plate all at once. ``--stiffness``
sets the elastic plates' spring factor (mpm.Collider.stiffness: k =
stiffness M dx^(d-2), M the body's P-wave modulus).

Per resolution it prints the table of windows (approach, force, closed
form, ratio) and then the ratios' range over the second half of the
loading. A bad argument ends it with one line (``error: --option: value;
accepted: ...``) and exit code 2.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_ERROR  # no start-up banner or module-load lines

import mpm  # noqa: E402
from mpm.hertz import contact_modulus, plates_load  # noqa: E402
from _args import Parser, bounded, choice, device, integer_list  # noqa: E402 (this folder)

SIDE = 0.25  # the box [m]
R = 0.08  # the body's radius [m]
E, NU = 1.0e5, 0.3  # the body's Young's modulus [Pa] and Poisson's ratio
E_SLAB, THICK = 2.0e6, 0.02  # the stiffer slab's modulus [Pa] and thickness [m]
WINDOWS = 10
PLATES = ("collider", "body")


@dataclass
class Pressed:
    """One run: per window, the plates' mean approach [m] and the mean force
    [N in 3D, N/m in 2D] of the upper plate on the body, and the closed form."""

    resolution: int
    approach: np.ndarray
    force: np.ndarray
    expected: np.ndarray
    steps: int
    seconds: float  # wall-clock, compilation included

    @property
    def ratio(self) -> np.ndarray:
        return self.force / self.expected

    def loaded(self) -> np.ndarray:
        """The ratios over the second half of the loading."""
        return self.ratio[len(self.ratio) // 2:]


class Force(mpm.Observer):
    """The upper collider's mean force on the body over each window (its
    impulse on all grids divided by the kernel's number of grids)."""

    def __init__(self, grids: int, window: float):
        self.grids, self.window = grids, window
        self.impulse, self.span, self.rows = 0.0, 0.0, []

    def on_step(self, driver, report):
        self.impulse += float(report.collider_impulse[0][1]) / self.grids
        self.span += report.dt
        if driver.time + 1e-12 >= (len(self.rows) + 1) * self.window:
            self.rows.append((driver.time - self.span / 2, -self.impulse / self.span))
            self.impulse, self.span = 0.0, 0.0


def scene(dim: int = 2, on: str = "collider", resolution: int = 64, rate: float = 0.02,
          boundary: str = "separate", sampling: str = "lattice", stiffness: float = 0.5) -> mpm.Scene:
    """The scene of the module docstring; the plates approach at ``rate``
    [m/s]; their ``boundary``: "separate" (the grid rule) or "elastic"
    (springs on the particles, mpm.elastic_contact; on the slab, the contact
    between the bodies too, mpm.body_springs); the ball's ``sampling``
    (mpm.sampling.SAMPLINGS); the elastic plates' spring ``stiffness``
    factor (mpm.Collider.stiffness)."""
    centre = (SIDE / 2,) * dim
    up = (0.0, 1.0) + (0.0,) * (dim - 2)

    def at(y):
        return (SIDE / 2, y) + (SIDE / 2,) * (dim - 2)

    def moving(sign):
        return tuple(sign * rate / 2 * u for u in up)
    ball = mpm.Body(mpm.Sphere(centre, R), mpm.FixedCorotated(E=E, nu=NU), name="ball", sampling=sampling)
    bodies, regions = [ball], []
    colliders = [mpm.Collider.half_space(at(SIDE / 2 + R), tuple(-u for u in up), boundary=boundary,
                                         velocity=moving(-1.0), name="upper", stiffness=stiffness)]
    bottom = SIDE / 2 - R
    if on == "collider":
        colliders.append(mpm.Collider.half_space(at(bottom), up, boundary=boundary, velocity=moving(1.0),
                                                 name="lower", stiffness=stiffness))
    else:
        dx = SIDE / resolution
        half = (SIDE / 2 - 4 * dx, THICK / 2) + (SIDE / 2 - 4 * dx,) * (dim - 2)
        bodies = [mpm.Body(mpm.Box(at(bottom - THICK / 2), half), mpm.FixedCorotated(E=E_SLAB, nu=NU), name="slab"),
                  ball]
        strip = mpm.Box(at(bottom - THICK + dx / 2), half[:1] + (dx / 2,) + half[2:])
        regions = [mpm.KinematicRegion(body=0, select=strip, velocity=moving(1.0))]
    return mpm.Scene(dim=dim, domain=(SIDE,) * dim, resolution=resolution, ppc=4 if dim == 2 else 8,
                     bodies=bodies, colliders=colliders, regions=regions, gravity=(0.0,) * dim,
                     walls=("slip",) * (2 * dim), contact="elastic" if boundary == "elastic" else "frictionless",
                     contact_normal="stiffer",
                     contact_share=0.1, contact_fill=1.0)


def press(dim: int = 2, on: str = "collider", scheme: str = "empm", resolution: int = 64, approach: float = 0.008,
          duration: float = 0.4, device: str = "cpu", boundary: str = "separate",
          sampling: str = "lattice", stiffness: float = 0.5) -> Pressed:
    """Press the body by ``approach`` [m] over ``duration`` [s] (module docstring)."""
    wall = time.perf_counter()
    rate = approach / duration
    model, state = mpm.build(scene(dim, on, resolution, rate, boundary, sampling, stiffness), mpm.QUADRATIC, "float32",
                             device)
    force = Force(model.kernel.n_grids, duration / WINDOWS)
    driver = mpm.Driver(mpm.Solver(model, mpm.SCHEMES[scheme]()), state, mpm.StepPolicy(duration=duration),
                        observers=[force])
    if driver.run().status != "completed":
        raise RuntimeError(f"the run stopped: {driver.outcome.reason}")
    t, F = np.array(force.rows).T
    rigid = contact_modulus(E, NU)
    lower = rigid if on == "collider" else contact_modulus(E, NU, E_SLAB, NU)
    expected = np.array([plates_load(rate * s, R, dim, rigid, lower) for s in t])
    return Pressed(resolution, rate * t, F, expected, driver.step, time.perf_counter() - wall)


def main(argv=None) -> int:
    parser = Parser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--dim", type=choice(("2", "3")), default="2", help="2 (a cylinder) or 3 (a sphere)")
    parser.add_argument("--on", type=choice(PLATES), default="collider", help=", ".join(PLATES))
    parser.add_argument("--scheme", type=choice(mpm.SCHEMES), default="empm", help=", ".join(mpm.SCHEMES))
    parser.add_argument("--resolutions", type=integer_list(16, 512), default=[64, 128],
                        help="comma-separated cells across the 0.25 m box")
    parser.add_argument("--approach", type=bounded(0.5, 16.0, "mm"), default=8.0,
                        help="the plates' approach at the end [mm]")
    parser.add_argument("--duration", type=bounded(0.05, 10.0, "s"), default=0.4, help="loading time [s]")
    parser.add_argument("--device", type=device, default="cpu", help="cpu, or cuda[:N] where there is one")
    parser.add_argument("--boundary", type=choice(("separate", "elastic")), default="separate",
                        help="the plates': separate (the grid rule) or elastic (springs on the particles)")
    parser.add_argument("--sampling", type=choice(mpm.sampling.SAMPLINGS), default="lattice",
                        help="the ball's particles: " + ", ".join(mpm.sampling.SAMPLINGS))
    parser.add_argument("--stiffness", type=bounded(0.05, 4.0, "-"), default=0.5,
                        help="the elastic plates' spring factor (mpm.Collider.stiffness)")
    args = parser.parse_args(argv)
    body = "cylinder [N/m]" if args.dim == "2" else "sphere [N]"
    print(f"a {body} between a rigid plate and a {args.on}, {args.scheme}: approach {args.approach:g} mm "
          f"over {args.duration:g} s, {args.sampling} sampling")
    for res in args.resolutions:
        p = press(int(args.dim), args.on, args.scheme, res, args.approach / 1000, args.duration, args.device,
                  args.boundary, args.sampling, args.stiffness)
        dx = SIDE / res
        print(f"\n{res} cells (dx = {1000 * dx:.3f} mm, R = {R / dx:.1f} dx), {p.steps} steps, {p.seconds:.0f} s")
        print(f"{'approach [mm]':>14} {'[dx]':>6} {'force':>10} {'closed':>10} {'ratio':>7}")
        for d, f, e, q in zip(p.approach, p.force, p.expected, p.ratio):
            print(f"{1000 * d:>14.3f} {d / dx:>6.2f} {f:>10.4g} {e:>10.4g} {q:>7.3f}")
        q = p.loaded()
        print(f"second half of the loading: force / closed form from {q.min():.3f} to {q.max():.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
