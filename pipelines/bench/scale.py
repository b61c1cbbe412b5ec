"""Cost at the papers' scale, its growth with size, and the cost of each
optional stage: the tables behind ``python -m pipelines.bench --paper``,
``--scaling`` and ``--stages``.

- paper: every scene of the A-ULMPM paper's Table 2 at the paper's particle
  count, a fixed number of steps with logging off, ms per step beside the
  paper's seconds per step (its CPUs: Intel i7-8750H, Xeon E5-1620 v4; its
  figure is the mean over a whole simulation, ours the median of the first
  steps).
- scaling: the elastic sphere (3D) and ball (2D) from about 10K (5K) to 1M
  particles: ms per step, particle-steps per second, the bytes of the run's
  Warp arrays per particle (mpm.memory) and the process's peak resident memory.
- large: the elastic sphere at about 1M and 10M particles (EMPM, the run's
  own read-back interval: every 10 steps with the CUDA graph on CUDA):
  steps per second after warm-up, host reads per step, the run's Warp
  arrays [MB] and the device's memory in use (``--large``; meant for a GPU).
- stages: the 2D ball with one optional stage added at a time (detection,
  logging, a kinematic region, a collider, open walls, a second body with
  contact) against the plain step, and the Warp launches and memory
  copies/fills of one solver step.
"""

from __future__ import annotations

import time
from pathlib import Path

import warp as wp

import mpm
from mpm.launch import Counter, Launches, kernel_name

from .runs import QUIET, execute, interleaved, spec_for, step_ms, timed
from ..run.runner import solver_options

# A-ULMPM Table 2 (journal version): scene label, overrides, seconds per step, machine, particles
PAPER_TABLE2 = [
    ("2D elastic ball", ["scene=elastic_ball_2d", "scene.size=paper", "scheme=aulmpm"], 0.0148, 1, "20K"),
    ("2D elastic ball, implicit", ["scene=elastic_ball_2d", "scene.size=paper", "scheme=aulmpm",
                                   "integrator=implicit"], 0.0165, 1, "20K"),
    ("2D rotation", ["scene=rotating_plate_2d", "scene.size=paper", "scheme=aulmpm"], 0.0571, 1, "42K"),
    ("2D droplet", ["scene=droplet_2d", "scene.size=paper", "scheme=aulmpm"], 0.0154, 1, "5K"),
    ("twisting bar", ["scene=twisting_bar", "scene.size=paper", "scheme=aulmpm"], 0.627, 1, "193.3K"),
    ("twisting bar (48K)", ["scene=twisting_bar", "scene.resolution=88", "scheme=aulmpm"], 0.125, 2, "48.3K"),
    ("stretchy yo-yo", ["scene=yoyo", "scene.size=paper", "scheme=aulmpm"], 1.314, 2, "179.3K"),
    ("snow bunny", ["scene=snow_bunnies", "scene.size=paper", "scheme=aulmpm"], 0.965, 2, "116.3K"),
    ("snow bunny, EMPM", ["scene=snow_bunnies", "scene.size=paper", "scheme=empm"], 0.971, 2, "116.3K"),
    ("water bunny", ["scene=water_bunny", "scene.size=paper", "scheme=aulmpm"], 0.341, 2, "96.3K"),
    ("water bunny, EMPM", ["scene=water_bunny", "scene.size=paper", "scheme=empm"], 0.381, 2, "96.3K"),
    ("FSI (bowl)", ["scene=bowl_fsi", "scene.size=paper", "scheme=aulmpm"], 0.934, 1, "169.1K"),
]
PAPER_STEPS = {2: 40, 3: 10}


def bench_paper(workdir: Path, repeats: int = 2) -> list[dict]:
    rows = []
    for label, over, paper_s, machine, paper_n in PAPER_TABLE2:
        over = over + QUIET + [f"run.steps={PAPER_STEPS[spec_for(over).scene.dim]}"]
        warm = execute(spec_for(over[:-1] + ["run.steps=2"]), workdir / "warm")  # compile
        m = timed(over, workdir / label.replace(" ", "_"), repeats)
        rows.append({"scene": label, "overrides": over, "particles": m["particles"], "paper_particles": paper_n,
                     "grid_nodes": m["grid_nodes"], "steps": m["steps"], "compile_time_s": warm["compile_time_s"],
                     "step_ms": m["step_time_ms"], "particle_steps_per_s": m["particle_steps_per_s"],
                     "paper_ms": 1e3 * paper_s, "paper_machine": machine,
                     "vs_paper": 1e3 * paper_s / m["step_time_ms"]})
    return rows


# resolutions that give about 10K ... 1M particles (3D sphere, 2D ball)
SCALING = {
    "sphere_3d": (["scene=elastic_ball_3d", "material=fixed_corotated"], (34, 50, 72, 104, 155), 10),
    "ball_2d": (["scene=elastic_ball_2d", "material=fixed_corotated"], (64, 133, 297, 515, 940), 20),
}


def bench_scaling(workdir: Path, repeats: int = 2) -> list[dict]:
    """Ascending sizes in one process, so that the peak resident memory after
    each is the peak of the largest run so far, that is of this one."""
    rows = []
    for case, (over, resolutions, steps) in SCALING.items():
        execute(spec_for(over + QUIET + [f"scene.resolution={resolutions[0]}", "run.steps=2"]), workdir / "warm")
        for res in resolutions:
            m = timed(over + QUIET + [f"scene.resolution={res}", f"run.steps={steps}"], workdir / f"{case}_{res}",
                      repeats)
            rows.append({"case": case, "resolution": res, "particles": m["particles"],
                         "grid_nodes": m["grid_nodes"], "step_ms": m["step_time_ms"],
                         "particle_steps_per_s": m["particle_steps_per_s"], "memory_mb": m["memory_mb"],
                         "bytes_per_particle": 1e6 * m["memory_mb"] / m["particles"],
                         "peak_rss_mb": m["peak_rss_mb"]})
    return rows


# sphere resolutions giving about 1M and 10M particles (the scaling table's 155 gives 1.0M)
LARGE = {"1M": 155, "10M": 334}
LARGE_CASE = ["scene=elastic_ball_3d", "material=fixed_corotated", "scheme=empm"]


def bench_large(steps: int = 50, rounds: int = 3, sizes: dict | None = None,
                energies: tuple = (True,)) -> list[dict]:
    """The sphere at each size of ``sizes`` (default LARGE): a started
    driver (no logging, no detection), then ``rounds`` timed batches of
    about ``steps`` steps, synchronised at their ends; the fastest batch.
    ``energies``: with the step's energy sums (kinetic, potential and the
    largest speed per body in G2P: what the blow-up detection reads), without, or both."""
    rows = []
    for label, res, energy in ((label, res, e) for label, res in (sizes or LARGE).items() for e in energies):
        spec = spec_for(LARGE_CASE + QUIET + [f"scene.resolution={res}"])
        device = spec.run.device
        t0 = time.perf_counter()
        driver = _driver(spec, track_energy=energy)
        wp.synchronize_device(device)
        setup_s = time.perf_counter() - t0
        best = None
        for _ in range(rounds):
            with Counter() as r:
                n, dt = advance(driver, steps, device)
            if best is None or dt / n < best[0]:
                best = (dt / n, r.reads / n)
        assert best is not None  # rounds >= 1
        per_step, reads = best
        dev = wp.get_device(device)
        in_use = (dev.total_memory - dev.free_memory) / 1e6 if dev.is_cuda else None
        rows.append({"size": label, "resolution": res, "energy": energy,
                     "particles": driver.solver.model.n_particles,
                     "device": device, "sync_every": driver.k, "setup_s": setup_s,
                     "step_ms": 1e3 * per_step, "steps_per_s": 1.0 / per_step,
                     "particle_steps_per_s": driver.solver.model.n_particles / per_step, "reads": reads,
                     "arrays_mb": driver.solver.memory_bytes(driver.state) / 1e6, "device_mb": in_use})
        del driver
    return rows


def print_large(rows: list[dict]) -> None:
    print("\nlarge: the 3D elastic sphere (EMPM, fixed corotated, quadratic MLS), no logging, no detection")
    print(f"{'size':<5} {'energy':<6} {'particles':>11} {'device':<7} {'k':>3} {'setup s':>8} {'ms/step':>9} "
          f"{'steps/s':>8} {'Gpart-steps/s':>13} {'reads/step':>10} {'arrays MB':>10} {'device MB':>10}")
    for r in rows:
        used = f"{r['device_mb']:>10,.0f}" if r["device_mb"] is not None else f"{'-':>10}"
        print(f"{r['size']:<5} {'sums' if r['energy'] else 'none':<6} {r['particles']:>11,} {r['device']:<7} "
              f"{r['sync_every']:>3} {r['setup_s']:>8.1f} "
              f"{r['step_ms']:>9.3f} {r['steps_per_s']:>8.1f} {r['particle_steps_per_s'] / 1e9:>13.3f} "
              f"{r['reads']:>10.2f} {r['arrays_mb']:>10,.0f} {used}")


STAGE_BASE = ["scene=elastic_ball_2d", "scene.resolution=128", "material=fixed_corotated", "scheme=empm",
              "detect.action=off"]
TWO_BALLS = ("scene.bodies=[{name:left,shape:{type:sphere,center:[0.3,0.6],radius:0.14}},"
             "{name:right,shape:{type:sphere,center:[0.7,0.6],radius:0.14}}]")
STAGES = {
    "plain step": [],
    "+ detection (energy, speed, inversion)": ["detect.action=stop"],
    "+ logging (particles, dJ, scalars every step)": ["log.every=1", "log.scalars=true"],
    "+ kinematic region": ["scene.regions=[{name:hold,body:ball,select:{type:box,center:[0.5,0.6],"
                           "half_size:[0.05,0.05]},velocity:[0.0,0.0]}]"],
    "+ collider (sphere)": ["scene.colliders=[{name:post,type:sphere,center:[0.15,0.15],radius:0.05}]"],
    "+ open top wall (removal)": ["scene.walls=[slip,slip,slip,open]"],
    "two balls, one shared grid": [TWO_BALLS, "scene.contact=shared"],
    "two balls, frictionless contact": [TWO_BALLS, "scene.contact=frictionless"],
}


def advance(driver, steps: int, device: str | None = None) -> tuple[int, float]:
    """``driver`` advanced by ``steps`` steps or more (whole batches), and
    the device synchronised where ``device`` is given: (steps taken, seconds)."""
    first = driver.step
    t0 = time.perf_counter()
    while driver.step < first + steps:
        driver.advance()
    if device is not None:
        wp.synchronize_device(device)
    return driver.step - first, time.perf_counter() - t0


def _driver(spec, sync_every: int | None = None, track_energy: bool | None = None):
    """A started driver of ``spec`` (mpm.Driver, no observers, no detection,
    reading back every ``sync_every`` steps: None, the run's own choice), one
    batch taken (the first steps size the grid arrays and compile nothing
    later)."""
    from ..run.runner import step_policy, sync_every as run_sync_every

    k = sync_every if sync_every is not None else run_sync_every(spec)
    options = solver_options(spec)
    options.batched = k > 1
    if track_energy is not None:
        options.track_energy = track_energy
    model, state = mpm.build(spec.scene, spec.kernel, spec.run.precision, spec.run.device, spec.seed)
    solver = mpm.Solver(model, spec.scheme, options)
    policy = step_policy(spec)
    policy.steps, policy.duration = 10**9, None
    driver = mpm.Driver(solver, state, policy, mpm.Detection(action="off"), sync_every=k)
    solver.load()
    driver.start()
    driver.advance()
    return driver


class _Counted:
    """Within the block, count and time kernel launches by kernel (the
    solver's recorded ones, mpm.launch, and plain wp.launch; synchronised on
    CUDA), and count array copies and fills."""

    def __init__(self, device: str):
        self.device = device
        self.launches, self.ms, self.memory = 0, {}, 0

    def __enter__(self):
        self._saved = wp.launch, wp.copy, wp.array.zero_, Launches.__call__
        launch, copy, zero, recorded = self._saved
        cuda = self.device.startswith("cuda")
        inside = []  # a recorded launch's first call goes through wp.launch: count it once

        def timed(fn, kernel_at):
            def wrapper(*args, **kwargs):
                if inside:
                    return fn(*args, **kwargs)
                kernel = args[kernel_at]
                self.launches += 1
                inside.append(True)
                t0 = time.perf_counter()
                try:
                    out = fn(*args, **kwargs)
                    if cuda:
                        wp.synchronize_device(self.device)
                finally:
                    inside.pop()
                name = kernel_name(kernel)
                self.ms[name] = self.ms.get(name, 0.0) + 1e3 * (time.perf_counter() - t0)
                return out
            return wrapper

        def counted(fn):
            def wrapper(*args, **kwargs):
                self.memory += 1
                return fn(*args, **kwargs)
            return wrapper

        wp.launch, wp.copy, wp.array.zero_ = timed(launch, 0), counted(copy), counted(zero)
        Launches.__call__ = timed(recorded, 1)
        return self

    def __exit__(self, *exc):
        wp.launch, wp.copy, wp.array.zero_, Launches.__call__ = self._saved


def launches_per_step(spec, steps: int = 5, sync_every: int | None = None) -> tuple[float, float, float]:
    """Warp kernel launches, array copies and fills, and device-to-host reads
    per step of the driver (no logging, no detection)."""
    driver = _driver(spec, sync_every)
    with _Counted(spec.run.device) as c, Counter() as r:
        n, _ = advance(driver, steps)
    return c.launches / n, c.memory / n, r.reads / n


PROFILE_CASES = {"ball_2d (128^2)": ["scene=elastic_ball_2d", "scene.resolution=128", "material=fixed_corotated"],
                 "sphere_3d (64^3)": ["scene=elastic_ball_3d", "scene.resolution=64", "material=fixed_corotated"]}


def profile(steps: int = 20, rounds: int = 3, cases: dict | None = None) -> list[dict]:
    """Where a step's time goes, per kernel (each launch timed, synchronised
    on CUDA) and the rest of the driver's step (host work: read-back, the
    layout, Python), EMPM with the defaults, the host reading back every
    step (so that no CUDA graph hides the launches); the fastest of ``rounds``."""
    rows = []
    for case, over in (cases or PROFILE_CASES).items():
        spec = spec_for(over + ["scheme=empm"])
        driver = _driver(spec, sync_every=1)
        best = None
        for _ in range(rounds):
            with _Counted(spec.run.device) as c:
                n, seconds = advance(driver, steps)
                total = 1e3 * seconds / n
            if best is None or total < best[0]:
                best = (total, {k: v / n for k, v in c.ms.items()})
        assert best is not None  # rounds >= 1
        total, ms = best
        for name, t in sorted(ms.items(), key=lambda kv: -kv[1]):
            rows.append({"case": case, "part": name, "ms": t, "share": t / total})
        rows.append({"case": case, "part": "host (read-back, layout, Python)", "ms": total - sum(ms.values()),
                     "share": 1.0 - sum(ms.values()) / total})
        rows.append({"case": case, "part": "step", "ms": total, "share": 1.0})
    return rows


def bench_stages(workdir: Path, steps: int = 300, rounds: int = 5) -> list[dict]:
    """Each stage in turn, ``rounds`` interleaved rounds, the fastest median;
    a logged row counts the logging time too."""
    runs = {name: STAGE_BASE + QUIET + extra for name, extra in STAGES.items()}
    best = interleaved(runs, [f"run.steps={steps}"], workdir / "stages", rounds)
    base = step_ms(best["plain step"])
    rows = []
    for name, m in best.items():
        launches, memory, reads = launches_per_step(spec_for(runs[name]))
        rows.append({"stage": name, "particles": m["particles"], "step_ms": m["step_time_ms"],
                     "log_ms": m["log_time_ms"] or 0.0, "vs_plain": step_ms(m) / base,
                     "launches": launches, "copies_fills": memory, "reads": reads})
    return rows


def print_profile(rows: list[dict]) -> None:
    print("\nprofile of a step (EMPM, defaults, mpm.Driver; each launch timed)")
    print(f"{'case':<17} {'part':<34} {'ms/step':>8} {'share':>6}")
    for r in rows:
        print(f"{r['case']:<17} {r['part']:<34} {r['ms']:>8.3f} {100 * r['share']:>5.0f}%")


def print_paper(rows: list[dict]) -> None:
    print("\nthe A-ULMPM paper's Table 2 scenes at its particle counts, logging off (fixed steps, median)")
    print(f"{'scene':<26} {'particles':>9} {'paper':>7} {'grid':>10} {'steps':>5} {'compile s':>9} "
          f"{'ms/step':>8} {'Mpart-steps/s':>13} {'paper ms':>9} {'paper/ours':>10}")
    for r in rows:
        print(f"{r['scene']:<26} {r['particles']:>9,} {r['paper_particles']:>7} {r['grid_nodes']:>10,} "
              f"{r['steps']:>5} {r['compile_time_s']:>9.2f} {r['step_ms']:>8.2f} "
              f"{r['particle_steps_per_s'] / 1e6:>13.2f} {r['paper_ms']:>9.1f} {r['vs_paper']:>9.1f}x")
    print("paper: seconds per step averaged over the whole simulation on its machine 1 (i7-8750H) or 2 "
          "(Xeon E5-1620 v4); ours: the median of the first steps on this machine")


def print_scaling(rows: list[dict]) -> None:
    print("\nscaling (EMPM, fixed corotated, quadratic MLS, step only)")
    print(f"{'case':<10} {'cells':>5} {'particles':>10} {'grid':>10} {'ms/step':>9} {'Mpart-steps/s':>13} "
          f"{'arrays MB':>9} {'B/particle':>10} {'peak RSS MB':>11}")
    for r in rows:
        rss = f"{r['peak_rss_mb']:>11.0f}" if r["peak_rss_mb"] is not None else f"{'-':>11}"
        print(f"{r['case']:<10} {r['resolution']:>5} {r['particles']:>10,} {r['grid_nodes']:>10,} "
              f"{r['step_ms']:>9.2f} {r['particle_steps_per_s'] / 1e6:>13.2f} {r['memory_mb']:>9.1f} "
              f"{r['bytes_per_particle']:>10.0f} {rss}")
    print("arrays: the Warp arrays of the model, state and solver (grids at capacity); peak RSS: the "
          "whole process, Python and the compiled kernels included")


def print_stages(rows: list[dict]) -> None:
    print(f"\noptional stages on the 2D ball (128^2, EMPM, quadratic MLS, {rows[0]['particles']:,} particles), "
          "one added at a time")
    print(f"{'stage':<46} {'ms/step':>8} {'log ms':>7} {'vs plain':>9} {'launches/step':>13} "
          f"{'copies+fills/step':>17} {'reads/step':>10}")
    for r in rows:
        print(f"{r['stage']:<46} {r['step_ms']:>8.3f} {r['log_ms']:>7.3f} {r['vs_plain']:>8.2f}x "
              f"{r['launches']:>13.1f} {r['copies_fills']:>17.1f} {r['reads']:>10.2f}")
    print("the two-ball rows have their own particles (two smaller balls): compare them with each other")
