"""A small parameter study with ``mpm`` alone: the same elastic disc
dropped onto the floor for several Young's moduli E, one row per value in a
CSV table and the peak compression against E in a PNG plot.

    python examples/stiffness_study.py [--E 2.5e4,5e4,1e5,2e5] [--duration 0.25]
                                       [--resolution 32] [--scheme aulmpm] [--device cpu] [--out study]

Each run drops a disc (radius 0.1 m, centre 0.3 m above the floor of a
1 m box, neo-Hookean, nu = 0.3, rho = 1000 kg/m^3) from rest under
gravity. Its peak compression is 1 - h_min / h_0, h the disc's height (the
highest particle's y less the lowest's): a stiffer disc squashes less. It
writes ``<out>/stiffness_study.csv`` (the columns in COLUMNS) and
``<out>/stiffness_study.png``, prints the table, and the exponent k of a
power law, compression ~ E^k, fitted through the rows. A bad argument ends
it with one line (``error: --option: value; accepted: ...``) and exit
code 2.
"""

from __future__ import annotations

import csv
import math
import time
from pathlib import Path

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_ERROR  # no start-up banner or module-load lines

import mpm  # noqa: E402
from _args import Parser, bounded_list, choice, device, integer, out_dir, positive  # noqa: E402 (this folder)

NAME = "stiffness_study"
COLUMNS = ("E_Pa", "status", "steps", "time_s", "mean_dt_s", "lowest_centre_m", "peak_compression",
           "peak_elastic_J", "run_s")
"""E [Pa]; the outcome; the steps taken and the time reached [s]; the mean
step [s]; the lowest centre of mass [m]; the peak compression [-]; the
largest elastic energy [J per m of depth]; the wall time of the run [s],
compilation on first use included."""


class Squash(mpm.Observer):
    """Per state reached: the disc's height [m] (highest particle less the
    lowest) and centre of mass [m]; per step the elastic energy [J] of the
    state it started from."""

    def __init__(self, mass: np.ndarray):
        self.mass = mass
        self.height, self.centre, self.elastic = [], [], []

    def on_start(self, driver: mpm.Driver) -> None:
        self._add(driver)

    def on_step(self, driver: mpm.Driver, report: mpm.StepReport) -> None:
        self.elastic.append(report.elastic)
        self._add(driver)

    def _add(self, driver: mpm.Driver) -> None:
        y = driver.state.x.numpy()[:, 1].astype(np.float64)
        self.height.append(y.max() - y.min())
        self.centre.append(self.mass @ y / self.mass.sum())


def drop(E: float, duration: float, resolution: int, scheme: str, device: str) -> dict:
    """One run: the disc of modulus ``E`` [Pa] dropped for ``duration`` [s]; its row of COLUMNS."""
    ball = mpm.Body(mpm.Sphere((0.5, 0.3), 0.1), mpm.NeoHookean(E=E, nu=0.3, rho=1000.0))
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=resolution, gravity=(0.0, -9.81), bodies=[ball])
    model, state = mpm.build(scene, mpm.QUADRATIC, "float32", device)
    solver = mpm.Solver(model, mpm.SCHEMES[scheme](), mpm.SolverOptions(track_energy=True))
    squash = Squash(model.mass.numpy().astype(np.float64))
    driver = mpm.Driver(solver, state, mpm.StepPolicy(duration=duration), observers=[squash])
    start = time.perf_counter()
    driver.run()
    run_s = time.perf_counter() - start
    h = np.array(squash.height)
    return dict(E_Pa=E, status=driver.outcome.status, steps=driver.step, time_s=driver.time,
                mean_dt_s=driver.time / max(driver.step, 1), lowest_centre_m=min(squash.centre),
                peak_compression=1.0 - h.min() / h[0], peak_elastic_J=max(squash.elastic, default=0.0),
                run_s=run_s)


def write_csv(rows: list[dict], path: Path) -> None:
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: f"{v:.6g}" if isinstance(v, float) else v for k, v in row.items()})


def plot(rows: list[dict], path: Path, duration: float) -> None:
    import matplotlib

    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt

    E = [r["E_Pa"] for r in rows]
    fig, ax = plt.subplots(figsize=(5, 3.6), layout="constrained")
    ax.plot(E, [100.0 * r["peak_compression"] for r in rows], "o-")
    ax.set_xscale("log")
    ax.set_xlabel("Young's modulus E [Pa]")
    ax.set_ylabel("peak compression [%]")
    ax.set_title(f"elastic disc dropped from rest, {duration:g} s", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def power_law(rows: list[dict]) -> float:
    """The exponent k of compression ~ E^k fitted through the rows (nan with
    fewer than two moduli or a row without compression)."""
    E = np.array([r["E_Pa"] for r in rows])
    c = np.array([r["peak_compression"] for r in rows])
    if len(set(E)) < 2 or not np.all(c > 0.0):
        return math.nan
    return float(np.polyfit(np.log(E), np.log(c), 1)[0])


def main(argv=None) -> int:
    parser = Parser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--E", type=bounded_list(1e3, 1e8, "Pa"), default=[2.5e4, 5e4, 1e5, 2e5],
                        help="Young's moduli, comma-separated [Pa]")
    parser.add_argument("--duration", type=positive("s"), default=0.25, help="simulated time of each run [s]")
    parser.add_argument("--resolution", type=integer(16, 128), default=32, help="grid cells across the 1 m box")
    parser.add_argument("--scheme", type=choice(mpm.SCHEMES), default="aulmpm", help=", ".join(mpm.SCHEMES))
    parser.add_argument("--device", type=device, default="cpu", help="cpu, or cuda[:N] where there is one")
    parser.add_argument("--out", type=out_dir, default=Path("study"), help="the folder for the table and plot")
    args = parser.parse_args(argv)
    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        parser.error(f"--out: {args.out}: {e.strerror}; accepted: a folder to write into or create")
    rows, widths = [], [max(len(c), 9) for c in COLUMNS]
    print(" ".join(f"{c:>{w}}" for c, w in zip(COLUMNS, widths)))
    for E in args.E:
        rows.append(drop(E, args.duration, args.resolution, args.scheme, args.device))
        print(" ".join(f"{v:>{w}.4g}" if isinstance(v, float) else f"{v:>{w}}"
                       for v, w in zip(rows[-1].values(), widths)))
    table, figure = args.out / f"{NAME}.csv", args.out / f"{NAME}.png"
    write_csv(rows, table)
    plot(rows, figure, args.duration)
    k = power_law(rows)
    print(f"peak compression ~ E^k with k = {k:.3f} (least squares in log-log)" if math.isfinite(k)
          else "peak compression ~ E^k: k needs two moduli or more, each with some compression")
    print(f"wrote {table} and {figure}")
    return 0 if all(r["status"] == "completed" for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
