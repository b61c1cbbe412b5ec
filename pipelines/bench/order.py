"""What particle order costs: the bench's 3D sphere (64^3, EMPM, fixed
corotated, float32) stepped with its particles in the order they were
sampled (lattice order, body by body: neighbours in memory are neighbours
in space) and in a random permutation of it, in interleaved rounds
(``python -m pipelines.bench --only order``).

The permutation moves every per-particle array of the model and the state
(positions, velocities, F, C, X, masses, volumes, bodies, regions, δJ)
before the solver is built, so both runs step the same particles. The
ratio bounds what keeping particles in cell order (a periodic sort) could
gain on this device: P2G's scatter and G2P's gather walk the grid in
particle order. Built from ``mpm`` directly (the permutation has no
configuration key); the time is the step alone, after 5 warm steps.
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

import mpm
from .peers import BALL_3D as SPHERE  # the same sphere as the Genesis table
from .runs import spec_for


def _driver(device: str, shuffled: bool, case: list[str] = SPHERE) -> mpm.Driver:
    """The case's driver, 5 steps in; ``shuffled``: its particles permuted."""
    spec = spec_for(case)
    model, state = mpm.build(spec.scene, spec.kernel, "float32", device, spec.seed)
    n = state.x.shape[0]
    order = np.random.default_rng(0).permutation(n) if shuffled else np.arange(n)
    for obj in (model, state):
        for a in vars(obj).values():
            if isinstance(a, wp.array) and a.ndim >= 1 and a.shape[0] == n:
                a.assign(a.numpy()[order])
    solver = mpm.Solver(model, spec.scheme, mpm.SolverOptions())
    driver = mpm.Driver(solver, state, mpm.StepPolicy(steps=10**9))
    driver.start()
    for _ in range(5):
        driver.advance()
    return driver


def bench_order(device: str, rounds: int = 3, steps: int = 20, case: list[str] = SPHERE) -> list[dict]:
    """ms per step of the sphere in sampled and in random particle order,
    the fastest of ``rounds`` interleaved rounds of ``steps`` steps."""
    drivers = {"sampled": _driver(device, False, case), "random": _driver(device, True, case)}
    best = {k: float("inf") for k in drivers}
    for _ in range(rounds):
        for k, d in drivers.items():
            wp.synchronize()
            t = time.perf_counter()
            for _ in range(steps):
                d.advance()
            wp.synchronize()
            best[k] = min(best[k], 1e3 * (time.perf_counter() - t) / steps)
    n = drivers["sampled"].state.x.shape[0]
    return [{"order": k, "particles": n, "step_ms": best[k], "vs_sampled": best[k] / best["sampled"],
             "rounds": rounds} for k in drivers]


def print_order(rows: list[dict], device: str) -> None:
    print(f"\nparticle order: the 3D sphere (64^3, EMPM, fixed corotated, {device}), step only, "
          f"fastest of interleaved rounds")
    print(f"{'order':<8} {'particles':>9} {'ms/step':>8} {'vs sampled':>10}")
    for r in rows:
        print(f"{r['order']:<8} {r['particles']:>9,} {r['step_ms']:>8.3f} {r['vs_sampled']:>9.3f}x")
