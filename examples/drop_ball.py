"""Drop an elastic disc onto the floor with ``mpm`` alone (no Hydra, no
Rerun): build the scene from Python, step it with the project's stability
policy (:class:`mpm.Driver`: the stable step, collapse and blow-up
detection, as ``python -m pipelines.run`` uses them), and read the results.

    python examples/drop_ball.py [--duration 0.4] [--scheme aulmpm] [--resolution 48] [--device cpu]

It prints the outcome, the steps taken and the energy of the disc before it
lands, at the floor and after. A bad argument ends it with one line
(``error: --option: value; accepted: ...``) and exit code 2.
"""

from __future__ import annotations

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_ERROR  # no start-up banner or module-load lines

import mpm  # noqa: E402
from _args import Parser, choice, device, integer, positive  # noqa: E402 (this folder)


class Trajectory(mpm.Observer):
    """Per state reached: the time [s], the disc's centre of mass [m], its
    kinetic, potential and elastic energy [J] (the steps' own figures: G2P
    sums the kinetic and potential energy when the solver tracks them, P2G
    the elastic energy of the state a step starts from)."""

    def __init__(self, mass: np.ndarray):
        self.mass = mass
        self.t, self.center, self.kinetic, self.potential, self.elastic = [], [], [], [], []

    def on_start(self, driver: mpm.Driver) -> None:
        names = driver.solver.diagnostics.names
        self._add(driver, driver.initial[names.index("kinetic_energy")],
                  driver.initial[names.index("potential_energy")])

    def on_step(self, driver: mpm.Driver, report: mpm.StepReport) -> None:
        self.elastic.append(report.elastic)  # of the previous state
        self._add(driver, report.kinetic, report.potential)

    def _add(self, driver: mpm.Driver, kinetic: float, potential: float) -> None:
        x = driver.state.x.numpy().astype(np.float64)
        self.t.append(driver.time)
        self.center.append(self.mass @ x / self.mass.sum())
        self.kinetic.append(kinetic)
        self.potential.append(potential)

    def total(self) -> np.ndarray:
        """Kinetic + potential + elastic energy [J] of every state but the last."""
        return np.add(self.kinetic[:-1], self.potential[:-1]) + np.array(self.elastic)


def drop(duration: float = 0.4, scheme: str = "aulmpm", device: str = "cpu", resolution: int = 48):
    """The disc (radius 0.1 m, centre 0.4 m above the floor of a 1 m box,
    neo-Hookean E = 1e5 Pa) dropped from rest under gravity; returns the
    driver and its trajectory."""
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=resolution, gravity=(0.0, -9.81),
                      bodies=[mpm.Body(mpm.Sphere((0.5, 0.4), 0.1), mpm.NeoHookean(E=1.0e5, nu=0.3, rho=1000.0))])
    model, state = mpm.build(scene, mpm.QUADRATIC, "float32", device)
    solver = mpm.Solver(model, mpm.SCHEMES[scheme](), mpm.SolverOptions(track_energy=True))
    trajectory = Trajectory(model.mass.numpy().astype(np.float64))
    driver = mpm.Driver(solver, state, mpm.StepPolicy(duration=duration), observers=[trajectory])
    driver.run()
    return driver, trajectory


def main(argv=None) -> int:
    parser = Parser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--duration", type=positive("s"), default=0.4, help="simulated time [s]")
    parser.add_argument("--scheme", type=choice(mpm.SCHEMES), default="aulmpm", help=", ".join(mpm.SCHEMES))
    parser.add_argument("--resolution", type=integer(16, 256), default=48, help="grid cells across the 1 m box")
    parser.add_argument("--device", type=device, default="cpu", help="cpu, or cuda[:N] where there is one")
    args = parser.parse_args(argv)
    driver, tr = drop(args.duration, args.scheme, args.device, args.resolution)
    out = driver.outcome
    print(f"{out.status} after {driver.step} steps, t = {driver.time:.4g} s "
          f"(mean step {driver.time / max(driver.step, 1):.3g} s){': ' + out.reason if out.reason else ''}")
    total = tr.total()
    heights = [c[1] for c in tr.center]
    lowest = int(np.argmin(heights[:len(total)]))  # the last state has no elastic energy
    # it reached the floor where its centre turned back up after its lowest point (else it is still falling)
    landed = lowest < len(total) - 1 and max(heights[lowest:]) > heights[lowest]
    rows = [("start", 0), ("falling", len(total) // 4)] + ([("at the floor", lowest)] if landed else []) + [
        ("end", len(total) - 1)]
    for label, k in rows:
        print(f"{label:>13}: t = {tr.t[k]:.3f} s, centre height {tr.center[k][1]:.4f} m, kinetic "
              f"{tr.kinetic[k]:.4g} J, elastic {tr.elastic[k]:.4g} J, total {total[k]:.4g} J")
    if not landed:
        print(f"{'at the floor':>13}: not reached in {driver.time:.4g} s (still falling: a longer --duration)")
    return 0 if out.status == "completed" else 1


if __name__ == "__main__":
    raise SystemExit(main())
