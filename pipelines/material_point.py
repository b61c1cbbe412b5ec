"""Stress against strain of one material at one material point, without a
grid (mpm.materials.point_driver): ``python -m pipelines.material_point``.

    python -m pipelines.material_point material=von_mises --path uniaxial --strain 0.03
    python -m pipelines.material_point material=sand material.friction_angle=35 --path oedometer
    python -m pipelines.material_point material=viscoplastic --path shear --strain 2 --rate 5
    python -m pipelines.material_point material=snow --path isotropic --strain -0.2 --cycle

Paths (strain: the Hencky strain ln(stretch) along x, or the shear gamma):
  uniaxial   stretch along x, lateral stresses zero (solved at every step)
  oedometer  stretch along x, lateral sides fixed (uniaxial strain)
  isotropic  the same stretch along every axis
  shear      simple shear v_x = gamma_dot y
``--cycle`` loads to the strain and back to zero. Writes a PNG (Cauchy stress
components, von Mises stress and pressure against the strain) and a CSV with
every step; material overrides use the ``material`` config group and fail
with one line naming the key, like ``pipelines.run``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

PATHS = ("uniaxial", "oedometer", "isotropic", "shear")
MAX_STEPS = 1_000_000  # steps of a path at most (a step costs a kernel launch)
DEFAULT_OUT = Path("outputs") / "material_point" / "stress_strain.png"  # (and .csv beside)


def strain_history(strain: float, steps: int, cycle: bool) -> np.ndarray:
    """The loading parameter at steps 0..n (to ``strain`` and, with ``cycle``, back)."""
    up = np.linspace(0.0, strain, steps + 1)
    return np.concatenate([up, up[-2::-1]]) if cycle else up


def drive(material, path: str, strain: float, steps: int, rate: float, dim: int, cycle: bool):
    """(loading parameter per step, mpm.materials.point_driver.PathResult)."""
    from mpm.materials.point_driver import MaterialPoint, deformation_path

    s = strain_history(strain, steps, cycle)
    dt = abs(strain) / steps / rate if strain else 1.0 / steps
    mp = MaterialPoint(material, dim)
    if path == "uniaxial":
        return s, mp.uniaxial_stress(np.exp(s), dt)
    F = np.tile(np.eye(dim), (len(s), 1, 1))
    if path == "oedometer":
        F[:, 0, 0] = np.exp(s)
    elif path == "isotropic":
        F = F * np.exp(s)[:, None, None]
    else:  # simple shear
        F[:, 0, 1] = s
    return s, mp.run(deformation_path(F), dt)


def table(s: np.ndarray, result) -> tuple[list[str], np.ndarray]:
    """Columns of the CSV: loading parameter, Cauchy stress components [Pa],
    pressure, von Mises stress, history variables."""
    sigma = result.cauchy[:, 0]
    d = sigma.shape[-1]
    p = -np.trace(sigma, axis1=-2, axis2=-1) / d
    dev = sigma + p[:, None, None] * np.eye(d)
    q = np.sqrt(1.5 * np.sum(dev * dev, axis=(-2, -1)))
    names = ["strain", "sigma_xx", "sigma_yy", "sigma_xy", "pressure", "von_mises", "history_0",
             "plastic_strain"]
    cols = [s, sigma[:, 0, 0], sigma[:, 1, 1], sigma[:, 0, 1], p, q, result.history[:, 0, 0],
            result.history[:, 0, 1]]
    return names, np.stack(cols, axis=1)


def plot(path: Path, names: list[str], data: np.ndarray, title: str, xlabel: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for k in range(1, 6):
        ax.plot(data[:, 0], data[:, k], label=names[k])
    ax.set_xlabel(xlabel)
    ax.set_ylabel("Cauchy stress [Pa]")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    from .config.arguments import Parser, finite, output_file

    parser = Parser(prog="python -m pipelines.material_point", description=__doc__,
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("overrides", nargs="*", help="material=<model> and material.<key>=<value>")
    parser.add_argument("--path", choices=PATHS, default="uniaxial")
    parser.add_argument("--strain", type=float, default=0.05, help="final Hencky strain (shear: gamma)")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--rate", type=float, default=1.0, help="strain rate [1/s] (sets dt)")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=3)
    parser.add_argument("--cycle", action="store_true", help="load, then unload to zero strain")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help=f"PNG (and .csv beside); default {DEFAULT_OUT}, its folder made")
    args = parser.parse_args(argv)
    bad = [o for o in args.overrides if not (o.startswith("material=") or o.startswith("material."))]
    if bad:
        print(f"error: {bad[0]}: not a material setting; accepted: material=<model>, material.<key>=<value>",
              file=sys.stderr)
        return 2
    problem = finite("--strain", args.strain) or finite("--rate", args.rate, 0.0, strict=True)
    if args.steps < 1 or args.steps > MAX_STEPS:
        problem = f"--steps: {args.steps}; accepted: an integer from 1 to {MAX_STEPS}"
    if not problem and args.out == DEFAULT_OUT:  # the project's outputs folder, not the working directory
        DEFAULT_OUT.parent.mkdir(parents=True, exist_ok=True)
    problem = problem or output_file("--out", args.out, ".png")
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    from hydra import compose, initialize_config_dir

    from .config import plugins, schema
    from .config.errors import describe
    from .config.validate import make_material
    from .run.warp_setup import init_warp

    conf = Path(__file__).resolve().parents[1] / "conf"
    try:
        plugins.prepare(args.overrides)  # MPM_PLUGINS and material=<dotted path> (pipelines.config.plugins)
        schema.register()
        with initialize_config_dir(config_dir=str(conf), version_base="1.3"):
            cfg = compose(config_name="config", overrides=args.overrides)
        material = make_material(cfg.material, "material")
    except Exception as e:
        message = describe(e)
        if message is None:
            raise
        print(f"error: {message}", file=sys.stderr)
        return 2
    init_warp()
    s, result = drive(material, args.path, args.strain, args.steps, args.rate, args.dim, args.cycle)
    names, data = table(s, result)
    csv = args.out.with_suffix(".csv")
    np.savetxt(csv, data, delimiter=",", header=",".join(names), comments="")
    xlabel = "shear gamma" if args.path == "shear" else "Hencky strain ln(stretch_x)"
    plot(args.out, names, data, f"{material.name}, {args.path}{' cycle' if args.cycle else ''}, "
         f"{args.dim}D", xlabel)
    peak = int(np.argmax(np.abs(data[:, 5])))
    print(f"{material.name} {args.path}: peak von Mises stress {data[peak, 5]:.6g} Pa at {names[0]} "
          f"{data[peak, 0]:.4g}; final pressure {data[-1, 4]:.6g} Pa, plastic strain {data[-1, 7]:.4g}; "
          f"{args.out}, {csv}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
