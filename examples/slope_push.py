"""Two elastic blocks slide down a rough slope in 3D; a body force pushes
one of them down the slope. Built with ``mpm`` alone: the slope is a rigid
collider (``mpm.Collider.half_space``, with Coulomb friction), the push an
external load (``mpm.Load.body_force``, ramped in), the scheme
A-ULMPM (by default).

    python examples/slope_push.py [--duration 0.3] [--friction 0.3] [--push 2]
                                  [--resolution 20] [--scheme aulmpm] [--device cpu]

A block on a plane inclined at theta with friction coefficient mu slides
with a = g (sin theta - mu cos theta) where that is > 0, else stays put;
the push, a force per volume rho b down the slope, adds b [m/s^2] to a
once ramped in. It prints each block's travel and velocity along the slope and its
acceleration (a line fitted to its velocity once it has settled on the
slope, after SETTLE) against these closed forms. The slope below the
blocks is about 0.45 m long: a fast block reaches the box's wall within
0.3 s or so. A bad argument ends it with one line (``error: --option:
value; accepted: ...``) and exit code 2.
"""

from __future__ import annotations

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_ERROR  # no start-up banner or module-load lines

import mpm  # noqa: E402
from _args import Parser, bounded, choice, device, integer, positive  # noqa: E402 (this folder)

G = 9.81  # [m/s^2]
THETA = 25.0  # the slope [deg]
RHO = 1000.0  # the blocks' density [kg/m^3]
RAMP = 0.02  # the push grows from 0 to full over this time [s]
SETTLE = 0.05  # the blocks settle on the slope within this time [s]; the fit starts after it


class AlongSlope(mpm.Observer):
    """Per state reached: the time [s] and each body's centre of mass [m]
    and mean velocity [m/s] projected on the downhill direction."""

    def __init__(self, model: mpm.Model, downhill: np.ndarray):
        self.m = model.mass.numpy().astype(np.float64)
        self.ranges = model.body_ranges
        self.down = downhill
        self.t, self.s, self.v = [], [], []

    def on_start(self, driver: mpm.Driver) -> None:
        self._add(driver)

    def on_step(self, driver: mpm.Driver, report: mpm.StepReport) -> None:
        self._add(driver)

    def _add(self, driver: mpm.Driver) -> None:
        x = driver.state.x.numpy().astype(np.float64)
        v = driver.state.v.numpy().astype(np.float64)
        s, u = [], []
        for start, count in self.ranges:
            m = self.m[start:start + count]
            s.append(m @ x[start:start + count] @ self.down / m.sum())
            u.append(m @ v[start:start + count] @ self.down / m.sum())
        self.t.append(driver.time)
        self.s.append(s)
        self.v.append(u)

    def acceleration(self) -> np.ndarray:
        """Per body: the slope of a line fitted to its velocity after SETTLE [m/s^2]."""
        t, v = np.array(self.t), np.array(self.v)
        after = t > SETTLE
        if after.sum() < 3:
            return np.full(v.shape[1], np.nan)
        return np.polyfit(t[after], v[after], 1)[0]


def slide(duration: float = 0.3, friction: float = 0.3, push: float = 2.0, resolution: int = 20,
          scheme: str = "aulmpm", device: str = "cpu"):
    """The two blocks (0.2 x 0.1 x 0.15 m, neo-Hookean E = 1e5 Pa, rho =
    1000 kg/m^3) placed at rest on a slope of THETA degrees in a
    1 m box, side by side; block 1 is pushed down the slope by ``push``
    [m/s^2] per unit mass. Returns the driver, the observer and the
    downhill direction."""
    th = np.radians(THETA)
    down = np.array([np.cos(th), -np.sin(th), 0.0])  # along the slope, downhill
    normal = np.array([np.sin(th), np.cos(th), 0.0])  # out of the slope
    foot = np.array([0.5, 0.35, 0.5])  # a point of the slope's surface [m]
    half = np.array([0.1, 0.05, 0.075])  # the blocks' half sizes: along, across the slope, sideways [m]
    turn = mpm.rotation_matrix((0.0, 0.0, -THETA), 3)  # x onto the downhill direction, y onto the normal
    blocks = []
    for z in (0.35, 0.65):
        c = foot - 0.2 * down + normal * half[1]  # 0.2 m uphill of the foot, on the slope
        c[2] = z
        blocks.append(mpm.Body(mpm.Rotated(mpm.Box(tuple(c), tuple(half)), turn),
                               mpm.NeoHookean(E=1.0e5, nu=0.3, rho=RHO)))
    slope = mpm.Collider.half_space(foot, normal, boundary="separate", friction=friction)
    pushed = mpm.Load.body_force(RHO * push * down, body=1, ramp=RAMP)
    scene = mpm.Scene(dim=3, domain=(1.0, 1.0, 1.0), resolution=resolution, gravity=(0.0, -G, 0.0),
                      walls=("slip",) * 6, ppc=8, bodies=blocks, colliders=[slope], loads=[pushed])
    model, state = mpm.build(scene, mpm.QUADRATIC, "float32", device)
    solver = mpm.Solver(model, mpm.SCHEMES[scheme]())
    track = AlongSlope(model, down)
    driver = mpm.Driver(solver, state, mpm.StepPolicy(duration=duration), observers=[track])
    driver.run()
    return driver, track, down


def expected(friction: float, push: float) -> tuple[float, float]:
    """The closed-form accelerations [m/s^2] down the slope: without and with the push."""
    th = np.radians(THETA)
    a = G * (np.sin(th) - friction * np.cos(th))
    return max(a, 0.0), max(a + push, 0.0)


def main(argv=None) -> int:
    parser = Parser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--duration", type=positive("s"), default=0.3, help="simulated time [s]")
    parser.add_argument("--friction", type=bounded(0.0, 2.0, "-"), default=0.3, help="Coulomb coefficient mu")
    parser.add_argument("--push", type=bounded(0.0, 10.0, "m/s^2"), default=2.0,
                        help="the body force on block 1 per unit mass, down the slope [m/s^2]")
    parser.add_argument("--resolution", type=integer(16, 48), default=20,
                        help="grid cells along each side of the 1 m box")
    parser.add_argument("--scheme", type=choice(mpm.SCHEMES), default="aulmpm", help=", ".join(mpm.SCHEMES))
    parser.add_argument("--device", type=device, default="cpu", help="cpu, or cuda[:N] where there is one")
    args = parser.parse_args(argv)
    driver, track, _ = slide(args.duration, args.friction, args.push, args.resolution, args.scheme, args.device)
    out = driver.outcome
    print(f"{out.status} after {driver.step} steps, t = {driver.time:.4g} s "
          f"(mean step {driver.time / max(driver.step, 1):.3g} s){': ' + out.reason if out.reason else ''}")
    print(f"slope {THETA:g} deg, friction {args.friction:g}, push {args.push:g} m/s^2 on block 1")
    s, v = np.array(track.s), np.array(track.v)
    fitted = track.acceleration()
    for k, (label, a) in enumerate(zip(("free", "pushed"), expected(args.friction, args.push))):
        fit = f"{fitted[k]:.3f} m/s^2" if np.isfinite(fitted[k]) else f"not fitted (needs a run past {SETTLE:g} s)"
        print(f"block {k} ({label:>6}): travelled {s[-1, k] - s[0, k]:.4f} m down the slope, velocity "
              f"{v[-1, k]:.3f} m/s, acceleration {fit} (closed form {a:.3f} m/s^2)")
    return 0 if out.status == "completed" else 1


if __name__ == "__main__":
    raise SystemExit(main())
