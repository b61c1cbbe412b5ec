"""A block sliding, or a disk rolling, on an anchored elastic plate with
Coulomb friction between the two bodies (``contact="friction"``), against
the closed forms.

    python examples/incline.py [--body block] [--scheme tlmpm] [--integrator explicit] [--friction 0.2]
        [--angle 0] [--speed 0.5] [--resolution 64] [--normal stiffer] [--share 0.1]
        [--fill 0.5] [--duration 0.1] [--device cpu]

The body (a block 0.09375 m square, or a disk of that diameter; E = 2e5 Pa)
starts at ``--speed`` on a plate (E = 2e6 Pa) whose bottom strip is held
still, its top on a row of grid nodes. ``--angle`` theta tilts gravity
(g = 9.81 m/s^2) by theta towards +x: the plate is a plane inclined at
theta, in its own frame. While the block slides (v > 0) Coulomb friction
gives it a = g (sin theta - mu cos theta); it sticks when a < 0 has stopped
it, and stays at rest from rest where tan theta <= mu. A solid disk rolls
without slipping at a = (2/3) g sin theta where mu >= tan(theta) / 3, and
slips at g (sin theta - mu cos theta) below. The script prints the body's
mean velocity at ten instants, its travel, its acceleration (a line fitted
to the samples from a quarter of the run on, until v falls below a quarter
of the speed) and the closed form. A bad argument ends it with one line
(``error: --option: value; accepted: ...``) and exit code 2.
"""

from __future__ import annotations

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_ERROR  # no start-up banner or module-load lines

import mpm  # noqa: E402
from mpm.inclines import rolling, sliding  # noqa: E402
from _args import Parser, bounded, choice, device, integer, positive  # noqa: E402 (this folder)

G = 9.81  # [m/s^2]
SPEED = 0.5  # the body's initial velocity [m/s]
BODIES = ("block", "disk")


def slide(scheme: str = "tlmpm", integrator: str = "explicit", friction: float = 0.2, resolution: int = 64,
          normal: str = "stiffer", share: float = 0.1, duration: float = 0.1, device: str = "cpu",
          samples: int = 10, angle: float = 0.0, speed: float = SPEED, body: str = "block",
          fill: float = 0.5) -> tuple[np.ndarray, ...]:
    """The body's mean x velocity [m/s] and travel [m] at ``samples``
    instants [s] of ``duration``, gravity tilted by ``angle`` [deg], the
    body's initial velocity ``speed`` [m/s], ``fill`` the volume fraction
    of a lattice node in contact (Scene.contact_fill). The domain is
    1 m x 0.5 m; the plate's top (y = 0.15625 m) lies on a row of nodes at
    any ``resolution`` from 64 that is a multiple of 32."""
    top, half = 0.15625, 0.046875  # [m]
    plate = mpm.Box((0.5, top - 0.04), (0.45, 0.04))
    centre = (0.25, top + half)
    shape = mpm.Box(centre, (half, half)) if body == "block" else mpm.Sphere(centre, half)
    bodies = [mpm.Body(plate, mpm.FixedCorotated(E=2.0e6, nu=0.3), name="plate"),
              mpm.Body(shape, mpm.FixedCorotated(E=2.0e5, nu=0.3), name=body, velocity=(speed, 0.0))]
    theta = np.radians(angle)
    scene = mpm.Scene(
        dim=2, domain=(1.0, 0.5), resolution=resolution, ppc=4, bodies=bodies,
        gravity=(G * np.sin(theta), -G * np.cos(theta)),
        contact="friction" if friction > 0 else "frictionless", contact_friction=friction,
        contact_normal=normal, contact_share=share, contact_fill=fill,
        regions=[mpm.KinematicRegion(body=0, select=mpm.Box((0.5, top - 0.07), (0.45, 0.011)), velocity=(0.0, 0.0))])
    model, state = mpm.build(scene, mpm.QUADRATIC, "float32", device)
    options = mpm.SolverOptions(integrator=mpm.INTEGRATORS[integrator]())
    solver = mpm.Solver(model, mpm.SCHEMES[scheme](), options)
    start, count = model.body_ranges[1]
    m = model.mass.numpy()[start:start + count].astype(np.float64)
    x0 = float(m @ state.x.numpy()[start:start + count, 0] / m.sum())
    t, v, travel = [], [], []
    for k in range(1, samples + 1):
        driver = mpm.Driver(solver, state, mpm.StepPolicy(duration=duration / samples))
        if driver.run().status != "completed":
            raise RuntimeError(f"the run stopped: {driver.outcome.reason}")
        t.append(k * duration / samples)
        v.append(float(m @ state.v.numpy()[start:start + count, 0] / m.sum()))
        travel.append(float(m @ state.x.numpy()[start:start + count, 0] / m.sum()) - x0)
    return np.array(t), np.array(v), np.array(travel)


def expected(angle: float, friction: float, speed: float = SPEED, body: str = "block") -> float:
    """The body's acceleration [m/s^2] in closed form (mpm.inclines): a
    block sliding, g (sin theta - mu cos theta), or 0 at rest that friction
    holds (tan theta <= mu); a solid disk, (2/3) g sin theta rolling
    (mu >= tan(theta) / 3), else slipping as the block slides."""
    if body == "disk":
        return rolling(angle, G, friction)
    return sliding(angle, G, friction, speed)


def acceleration(t: np.ndarray, v: np.ndarray, speed: float = SPEED) -> float:
    """dv/dt [m/s^2] of the line fitted to the samples from a quarter of the
    run on (the normal load settles first: the block starts without its
    weight on the plate) while the block slides: until v first falls below
    speed / 4, or all of them from rest."""
    n = len(v) if speed == 0.0 else int(np.argmax(np.append(v, -np.inf) < speed / 4))
    use = np.arange(len(v)) < n
    settled = use & (t >= t[-1] / 4)
    if settled.sum() >= 3:
        return float(np.polyfit(t[settled], v[settled], 1)[0])
    t, v = np.concatenate([[0.0], t[use]]), np.concatenate([[speed], v[use]])  # through (0, speed)
    return float(np.polyfit(t, v, 1)[0])


def main(argv=None) -> int:
    parser = Parser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--body", type=choice(BODIES), default="block", help=", ".join(BODIES))
    parser.add_argument("--scheme", type=choice(mpm.SCHEMES), default="tlmpm", help=", ".join(mpm.SCHEMES))
    parser.add_argument("--integrator", type=choice(mpm.INTEGRATORS), default="explicit",
                        help=", ".join(mpm.INTEGRATORS))
    parser.add_argument("--friction", type=bounded(0.0, 2.0, "-"), default=0.2, help="Coulomb mu")
    parser.add_argument("--angle", type=bounded(0.0, 60.0, "deg"), default=0.0, help="the incline [deg]")
    parser.add_argument("--speed", type=bounded(0.0, 5.0, "m/s"), default=SPEED, help="initial speed [m/s]")
    parser.add_argument("--resolution", type=integer(64, 256, step=32), default=64, help="cells across 1 m")
    parser.add_argument("--normal", type=choice(mpm.CONTACT_NORMALS), default="stiffer",
                        help=", ".join(mpm.CONTACT_NORMALS))
    parser.add_argument("--share", type=bounded(0.0, 0.9, "-"), default=0.1, help="scene.contact_share")
    parser.add_argument("--fill", type=bounded(0.01, 1.0, "-"), default=0.5, help="scene.contact_fill")
    parser.add_argument("--duration", type=positive("s"), default=0.1, help="simulated time [s]")
    parser.add_argument("--device", type=device, default="cpu", help="cpu, or cuda[:N] where there is one")
    args = parser.parse_args(argv)
    t, v, travel = slide(args.scheme, args.integrator, args.friction, args.resolution, args.normal, args.share,
                 args.duration, args.device, angle=args.angle, speed=args.speed, body=args.body, fill=args.fill)
    print("t [s]:   " + " ".join(f"{x:7.3f}" for x in t))
    print("v [m/s]: " + " ".join(f"{x:7.4f}" for x in v))
    print(f"travel {travel[-1]:.3e} m ({travel[-1] * args.resolution:.4f} cells)")
    print(f"acceleration {acceleration(t, v, args.speed):.4f} m/s^2; "
          f"closed form {expected(args.angle, args.friction, args.speed, args.body):.4f} m/s^2")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
