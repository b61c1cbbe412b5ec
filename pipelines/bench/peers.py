"""The same scene in a peer code, timed in the same process: the bench's
``peers`` table (``python -m pipelines.bench --only peers``).

Taichi's MLS-MPM (the 88-line scheme with a fixed-corotated stress, as in
Taichi's ``mpm128`` example; taichi 1.7, not a dependency: the table says
so when it is missing) steps the 2D elastic ball's own particles (the same
positions, masses, volumes, E and nu, 128^2 cells, quadratic B-spline, MLS,
gravity, separating walls 3 cells thick) at a fixed step, on one CPU thread
(``cpu_max_num_threads=1``: a Warp CPU launch runs on one thread, so this
is the per-core comparison) or on the GPU. Ours is the same ball through
``pipelines.run`` with logging off (the full step: the time-step policy,
the stability figures, the walls). Interleaved rounds, the fastest median
of each; the ratio is Taichi's ms per step over ours.

Genesis's MPM (genesis-world 1.4, its CPU backend on one thread; too large
to share this project's environment: ``--genesis-python`` names a Python
where it is installed) steps the 3D elastic ball (64^3 cells, fixed
corotated, ours EMPM MLS) in a process of its own
(pipelines/bench/genesis_peer.py), in rounds interleaved with ours. Genesis
samples its own particles (particle size dx / 2, as our 8 per cell), so
the counts differ slightly: the table gives both, the ratio of ms per step
and the ratio of particle-steps per second.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np

import mpm
from mpm.materials.base import Isotropic

from .runs import QUIET, WARM, interleaved, spec_for

BALL_2D = ["scene=elastic_ball_2d", "scene.resolution=128", "material=fixed_corotated", "scheme=empm"]
ROUNDS = 3
STEPS = 400
DT = 1.0e-4  # Taichi's fixed step [s] (the cost of a step does not depend on it)


def taichi_ball(device: str, steps: int = STEPS):
    """A callable timing ``steps`` Taichi steps (median ms per step over
    blocks of 20), or None when taichi is not installed."""
    try:
        import taichi as ti  # pyright: ignore[reportMissingImports]  # optional peer, not in the venv
    except ImportError:
        return None
    spec = spec_for(BALL_2D)
    model, state = mpm.build(spec.scene, spec.kernel, "float32", "cpu", spec.seed)
    x0 = state.x.numpy().astype(np.float32)
    m_p = float(model.mass.numpy()[0])
    V_p = float(model.volume.numpy()[0])
    mat = spec.scene.bodies[0].material
    assert isinstance(mat, Isotropic)  # BALL_2D: fixed_corotated
    mu, la = mat.E / (2 * (1 + mat.nu)), mat.E * mat.nu / ((1 + mat.nu) * (1 - 2 * mat.nu))
    n_grid, dx = round(1.0 / spec.scene.dx), spec.scene.dx
    inv_dx, g, bound = 1.0 / dx, -spec.scene.gravity[1], spec.scene.wall_cells
    if device == "cpu":
        ti.init(arch=ti.cpu, cpu_max_num_threads=1, default_fp=ti.f32, offline_cache=True, log_level="error")
    else:
        ti.init(arch=ti.cuda, default_fp=ti.f32, offline_cache=True, log_level="error")
    n = len(x0)
    x = ti.Vector.field(2, ti.f32, n)
    v = ti.Vector.field(2, ti.f32, n)
    C = ti.Matrix.field(2, 2, ti.f32, n)
    F = ti.Matrix.field(2, 2, ti.f32, n)
    grid_v = ti.Vector.field(2, ti.f32, (n_grid, n_grid))
    grid_m = ti.field(ti.f32, (n_grid, n_grid))

    @ti.kernel
    def reset():
        for p in F:
            F[p] = ti.Matrix.identity(ti.f32, 2)
            v[p] = ti.Vector.zero(ti.f32, 2)
            C[p] = ti.Matrix.zero(ti.f32, 2, 2)

    @ti.kernel
    def substep():
        for i, j in grid_m:
            grid_v[i, j] = ti.Vector.zero(ti.f32, 2)
            grid_m[i, j] = 0.0
        for p in x:  # P2G
            base = (x[p] * inv_dx - 0.5).cast(int)
            fx = x[p] * inv_dx - base.cast(ti.f32)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
            F[p] = (ti.Matrix.identity(ti.f32, 2) + DT * C[p]) @ F[p]
            U, sig, V = ti.svd(F[p])
            J = F[p].determinant()
            stress = 2 * mu * (F[p] - U @ V.transpose()) @ F[p].transpose() + \
                ti.Matrix.identity(ti.f32, 2) * la * J * (J - 1)
            stress = (-DT * V_p * 4 * inv_dx * inv_dx) * stress
            affine = stress + m_p * C[p]
            for i, j in ti.static(ti.ndrange(3, 3)):
                offset = ti.Vector([i, j])
                dpos = (offset.cast(ti.f32) - fx) * dx
                weight = w[i][0] * w[j][1]
                grid_v[base + offset] += weight * (m_p * v[p] + affine @ dpos)
                grid_m[base + offset] += weight * m_p
        for i, j in grid_m:  # grid update, separating walls
            if grid_m[i, j] > 0:
                grid_v[i, j] = (1 / grid_m[i, j]) * grid_v[i, j]
                grid_v[i, j][1] -= DT * g
                if i < bound and grid_v[i, j][0] < 0:
                    grid_v[i, j][0] = 0
                if i > n_grid - bound and grid_v[i, j][0] > 0:
                    grid_v[i, j][0] = 0
                if j < bound and grid_v[i, j][1] < 0:
                    grid_v[i, j][1] = 0
                if j > n_grid - bound and grid_v[i, j][1] > 0:
                    grid_v[i, j][1] = 0
        for p in x:  # G2P
            base = (x[p] * inv_dx - 0.5).cast(int)
            fx = x[p] * inv_dx - base.cast(ti.f32)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
            new_v = ti.Vector.zero(ti.f32, 2)
            new_C = ti.Matrix.zero(ti.f32, 2, 2)
            for i, j in ti.static(ti.ndrange(3, 3)):
                dpos = ti.Vector([i, j]).cast(ti.f32) - fx
                g_v = grid_v[base + ti.Vector([i, j])]
                weight = w[i][0] * w[j][1]
                new_v += weight * g_v
                new_C += 4 * inv_dx * weight * g_v.outer_product(dpos)
            v[p], C[p] = new_v, new_C
            x[p] += DT * v[p]

    def run() -> float:
        x.from_numpy(x0)
        reset()
        substep()
        ti.sync()
        times = []
        for _ in range(steps // 20):
            t0 = time.perf_counter()
            for _ in range(20):
                substep()
            ti.sync()
            times.append(1e3 * (time.perf_counter() - t0) / 20)
        return float(np.median(times))

    return run, n


def bench_peers(workdir: Path, device: str, rounds: int = ROUNDS) -> list[dict]:
    """Ours and Taichi's on the 2D ball, ``rounds`` interleaved rounds."""
    peer = taichi_ball(device)
    if peer is None:
        return [{"peer": "taichi", "missing": True}]
    run_taichi, n = peer
    ours, theirs = None, None
    for k in range(rounds):
        m = interleaved({"ours": BALL_2D + QUIET}, [f"run.steps={STEPS}"], workdir / f"peers{k}", 1,
                        warm=WARM if k == 0 else None)["ours"]
        ours = m["step_time_ms"] if ours is None else min(ours, m["step_time_ms"])
        t = run_taichi()
        theirs = t if theirs is None else min(theirs, t)
    assert ours is not None and theirs is not None  # rounds >= 1
    return [{"peer": "taichi", "missing": False, "particles": n, "ours_ms": ours, "taichi_ms": theirs,
             "ratio": theirs / ours, "threads": 1 if device == "cpu" else None, "rounds": rounds}]


BALL_3D = ["scene=elastic_ball_3d", "scene.resolution=64", "material=fixed_corotated", "scheme=empm"]
GENESIS_STEPS = 60
GENESIS_SCRIPT = Path(__file__).with_name("genesis_peer.py")


def genesis_python_problem(python: str) -> str | None:
    """What is wrong with ``python`` as the Genesis peer's interpreter (not
    an executable file, or genesis not importable there: looked up, not
    imported), or None."""
    path = shutil.which(python)
    if path is None or not os.path.isfile(path):
        return "no such executable"
    probe = "import importlib.util, sys; sys.exit(importlib.util.find_spec('genesis') is None)"
    try:
        found = subprocess.run([path, "-c", probe], capture_output=True, timeout=60).returncode == 0
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"does not run ({e})"
    return None if found else "genesis is not installed there"


def genesis_ball(python: str, steps: int = GENESIS_STEPS, timeout: float = 1800.0) -> dict:
    """Genesis's ms per step on the bench's 3D ball, run by ``python`` (a
    Python with genesis-world installed): {particles, ms_per_step, build_s,
    threads, genesis}."""
    spec = spec_for(BALL_3D)
    body = spec.scene.bodies[0]
    mat, shape = body.material, body.shape
    assert isinstance(mat, Isotropic) and isinstance(shape, mpm.Sphere)  # BALL_3D: an elastic ball
    args = {"dt": DT, "gravity": list(spec.scene.gravity), "domain": list(spec.scene.domain),
            "grid_density": round(1.0 / spec.scene.dx), "particle_size": spec.scene.dx / 2,
            "E": mat.E, "nu": mat.nu, "rho": mat.rho, "center": list(shape.center), "radius": shape.radius,
            "warm": 5, "steps": steps}
    out = subprocess.run([python, str(GENESIS_SCRIPT), json.dumps(args)], capture_output=True, text=True,
                         timeout=timeout)
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or [f"exit code {out.returncode}"])[-1]
        raise RuntimeError(f"the Genesis peer failed ({python}): {last}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def bench_genesis(workdir: Path, python: str | None, rounds: int = ROUNDS) -> list[dict]:
    """Ours and Genesis's on the 3D ball, ``rounds`` interleaved rounds (the
    fastest median of each); ``python`` None: not measured."""
    if not python:
        return [{"peer": "genesis", "missing": True}]
    ours = theirs = None
    for k in range(rounds):
        m = interleaved({"ours": BALL_3D + QUIET}, [f"run.steps={GENESIS_STEPS}"], workdir / f"genesis{k}", 1,
                        warm=WARM if k == 0 else None)["ours"]
        ours = m if ours is None or m["step_time_ms"] < ours["step_time_ms"] else ours
        try:
            g = genesis_ball(python)
        except (RuntimeError, subprocess.TimeoutExpired, ValueError) as e:  # ValueError: no JSON line
            return [{"peer": "genesis", "missing": False, "failed": str(e)}]
        theirs = g if theirs is None or g["ms_per_step"] < theirs["ms_per_step"] else theirs
    assert ours is not None and theirs is not None  # rounds >= 1
    n_ours, n_theirs = ours["particles"], theirs["particles"]
    return [{"peer": "genesis", "missing": False, "version": theirs["genesis"], "threads": theirs["threads"],
             "particles": n_ours, "genesis_particles": n_theirs, "ours_ms": ours["step_time_ms"],
             "genesis_ms": theirs["ms_per_step"], "ratio": theirs["ms_per_step"] / ours["step_time_ms"],
             "throughput_ratio": (n_ours / ours["step_time_ms"]) / (n_theirs / theirs["ms_per_step"]),
             "rounds": rounds}]


def print_genesis(rows: list[dict]) -> None:
    print("\npeers: the 3D elastic ball (64^3, EMPM MLS, fixed corotated) against Genesis's MPM "
          "(CPU backend, one thread), fastest median of interleaved rounds")
    for r in rows:
        if r["missing"]:
            print("genesis not measured (--genesis-python PYTHON: a Python with genesis-world installed)")
            continue
        if r.get("failed"):
            print(f"genesis not measured: {r['failed']}")
            continue
        print(f"{'ours: particles':>15} {'ms':>8} {'genesis: particles':>18} {'ms':>8} {'genesis / ours':>14} "
              f"{'per particle':>12} {'rounds':>6}")
        print(f"{r['particles']:>15,} {r['ours_ms']:>8.3f} {r['genesis_particles']:>18,} {r['genesis_ms']:>8.3f} "
              f"{r['ratio']:>13.2f}x {r['throughput_ratio']:>11.2f}x {r['rounds']:>6}")
        print(f"(genesis-world {r['version']}, {r['threads']} thread; 'per particle': ours particle-steps per "
              f"second over Genesis's)")


def print_peers(rows: list[dict], device: str) -> None:
    print(f"\npeers: the 2D elastic ball (128^2, EMPM MLS, fixed corotated) against Taichi's MLS-MPM "
          f"({'one CPU thread' if device == 'cpu' else device}), fastest median of interleaved rounds")
    for r in rows:
        if r["missing"]:
            print("taichi is not installed (pip install taichi==1.7.4): no comparison")
            continue
        print(f"{'particles':>9} {'ours ms':>8} {'taichi ms':>9} {'taichi / ours':>13} {'rounds':>6}")
        print(f"{r['particles']:>9,} {r['ours_ms']:>8.3f} {r['taichi_ms']:>9.3f} {r['ratio']:>12.2f}x {r['rounds']:>6}")
