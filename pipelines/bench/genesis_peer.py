"""Genesis's MPM on the 3D elastic ball, timed in a Python of its own:
``<genesis python> genesis_peer.py '<json>'`` prints one JSON line.

Genesis (genesis-world, with torch; not a dependency of this project, and
too large to share its environment) runs on its CPU backend with one
thread (``QD_NUM_THREADS=1``, its own default on the CPU; the process is
also pinned to one core): the per-core comparison, as a Warp CPU launch
uses one core. The ball is the bench's: a sphere of the same centre,
radius, E, nu and density, a fixed-corotated elastic material
(``MPM.Elastic(model="corotation")``), gravity, the unit box at
``grid_density`` cells per metre, particles sampled by Genesis at
``particle_size`` [m] (its count is reported: Genesis's sampler sets it).
One ``scene.step()`` is one substep (``substeps=1``) of ``dt`` [s]; the
time is the median of blocks of 10 steps after ``warm`` steps, in ms per
step. Imports nothing from this project."""

from __future__ import annotations

import json
import os
import sys
import time


def main(args: dict) -> dict:
    os.environ.setdefault("QD_NUM_THREADS", "1")
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    import genesis as gs  # pyright: ignore[reportMissingImports]  # optional peer (its own Python)
    import numpy as np

    t0 = time.perf_counter()
    gs.init(backend=gs.cpu, precision="32", logging_level="warning")
    scene = gs.Scene(
        sim_options=gs.options.SimOptions(dt=args["dt"], substeps=1, gravity=tuple(args["gravity"])),
        mpm_options=gs.options.MPMOptions(lower_bound=(0.0, 0.0, 0.0), upper_bound=tuple(args["domain"]),
                                          grid_density=args["grid_density"], particle_size=args["particle_size"]),
        show_viewer=False)
    ball = scene.add_entity(
        material=gs.materials.MPM.Elastic(E=args["E"], nu=args["nu"], rho=args["rho"], model="corotation"),
        morph=gs.morphs.Sphere(pos=tuple(args["center"]), radius=args["radius"]))
    scene.build()
    scene.step()
    build_s = time.perf_counter() - t0
    for _ in range(args["warm"]):
        scene.step()
    times = []
    for _ in range(args["steps"] // 10):
        t = time.perf_counter()
        for _ in range(10):
            scene.step()
        times.append(1e3 * (time.perf_counter() - t) / 10)
    return {"particles": int(ball.n_particles), "ms_per_step": float(np.median(times)), "build_s": build_s,
            "threads": int(os.environ["QD_NUM_THREADS"]), "genesis": gs.__version__}


if __name__ == "__main__":
    print(json.dumps(main(json.loads(sys.argv[1]))))
