"""Speed of the solver, of logging and of configuration updates:
``python -m pipelines.bench``.

Everything runs through the same code path as ``pipelines.run``
(:func:`pipelines.run.runner.execute`), after a warm-up run, in one process:

1. speed (EMPM): the 2D elastic ball (128^2 grid) and a 3D elastic sphere
   (64^3), each twice: step only (no particles, no scalars) and logged
   (particles, dJ and scalars every step). Particles, grid nodes, compile (or
   cache load) time, median ms per step, particle-steps per second, logging
   overhead (logged step + logging time against the step-only time).
   peers: the same 2D ball against Taichi's MLS-MPM on one CPU thread
   (pipelines.bench.peers; taichi is optional: the table says when it is
   missing), the ratio of their ms per step in interleaved rounds.
2. schemes: EMPM, TLMPM and A-ULMPM on the same 2D ball and 3D sphere, step
   only, in flight (as the speed table: far from the walls, where the
   Lagrangian schemes sum no node positions) and placed at the floor (within
   the wall band's reach from the first step: they sum them every step).
3. fluids: the 2D droplet at the paper's size (about 6.7K particles on
   128^2) and the 3D water drop (32^3) to 0.5 s with EMPM, A-ULMPM (fluid
   defaults) and A-ULMPM with the paper's criterion, in interleaved rounds:
   configuration updates per 10^4 steps (the paper's tau), the mean update
   cost per step and their ratio (the paper claims 4.27x to 31.52x less
   update overhead for A-ULMPM), steps, and the total stepping time against
   EMPM's.
4. kernels: the compact kernel against the quadratic B-spline on the 3D
   sphere (same particles, same dx), neo-Hookean (so that the transfers, not
   a 3x3 SVD, carry the cost), with the PIC transfer (like the CK-MPM paper's
   Taichi pipeline) and MLS, under TLMPM (weights cached at the initial
   configuration) and EMPM (weights, and the compact kernel's per-particle
   moment matrix, rebuilt every step).
5. materials: every constitutive model on the 3D sphere (EMPM, step only)
   against fixed corotated: the cost of the return mappings (an SVD, the
   flow rule and a principal-space stress per particle per step, in P2G).
6. integrators: the 2D elastic ball at the A-ULMPM paper's size (20K
   particles) for its whole 1 s bounce at one fixed step, explicit, implicit
   (Newton to 1e-4) and the paper's semi-implicit update (one Newton step),
   in interleaved rounds: ms per step (median and mean: an implicit step
   costs little in free fall and most in contact), the ratio to explicit
   (the paper's Table 2: 0.0165 / 0.0148 s = 1.11), Newton and CG
   iterations per step.

7. fused: EMPM with the stencils located in P2G and G2P and the
   configuration update done in G2P (``run.fuse=true``) against cached at
   an update pass of its own (``false``), on the 2D ball and the 3D sphere,
   quadratic MLS and PIC, compact MLS and PIC (``run.fuse`` null picks the
   fused path for the quadratic and cubic kernels).
8. sync: the 2D ball and the 3D sphere with the host reading back every step
   and every 10 steps (mpm.stepping.driver; with the CUDA graph on CUDA): ms per
   step, read-backs and kernel launches per step, the ratio to k = 1.
9. stages: the 2D ball with one optional stage added at a time, and the
   launches per step; profile: where a step's time goes, per kernel and
   host work, on the 2D ball and the 3D sphere (pipelines.bench.scale).
10. precision: plain float32, float32 with compensated sums of x and F
   (``run.compensate=true``) and float64 on the 2D ball, the 3D sphere and
   the small-deflection cantilever, EMPM and TLMPM (pipelines.bench.precision).
11. order (``--only order`` alone, not in the default run): the 3D sphere
   with its particles in sampled and in random order (pipelines.bench.order):
   what a cell-order sort could gain on this device.
12. checkpoint (``--only checkpoint`` alone): a checkpoint's write time and
   size, its share of the run at the default interval, and a resumed run's
   start-up on the 2D ball and the 3D ball at 100K+ particles
   (pipelines.bench.checkpoint).
13. gpu-profile (``--only gpu-profile`` alone): where a step's time goes on
   the device at 1M and 10M particles (``--profile-sizes``), per kernel,
   with the bytes each kernel moves and its share of the copy bandwidth
   (pipelines.bench.gpu_profile; meant for a GPU).

``--large`` adds the sphere at 1M and 10M particles (pipelines.bench.scale;
meant for a GPU) and ``--sweep`` the runs per hour of a sweep of 2N jobs on
1 and N workers (pipelines.bench.throughput).

``--device`` picks the Warp device of every run (default: run.device's,
CUDA where Warp finds a GPU). ``--paper`` adds the A-ULMPM paper's Table 2 scenes at its particle counts
and ``--scaling`` the growth of cost and memory from about 10K to 1M
particles (pipelines.bench.scale; minutes each); ``--only`` picks tables.

Each timed configuration runs five times and the fastest median counts
(the machine's noise only ever adds time). ``--cold`` compiles into an empty
kernel cache to time a first compile.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

from . import checkpoint, gpu_profile, order, peers, precision, scale, throughput
from ..config import schema
from .runs import QUIET, RECORDING, execute, interleaved, loop_s, spec_for, timed
from ..run.warp_setup import init_warp

CASES = {
    "ball_2d": ["scene=elastic_ball_2d", "scene.resolution=128", "material=fixed_corotated"],
    "ball_3d": ["scene=elastic_ball_3d", "scene.resolution=64", "material=fixed_corotated"],
}
STEPS = {"ball_2d": 400, "ball_3d": 60}
SCHEMES = ("empm", "tlmpm", "aulmpm")
FLUIDS = {"droplet_2d": ["scene=droplet_2d", "scene.resolution=128", "run.duration=0.5"],
          "water_drop_3d": ["scene=water_drop_3d", "scene.resolution=32", "run.duration=0.5"]}
KERNEL_CASE = ["scene=elastic_ball_3d", "scene.resolution=64", "material=neo_hookean"]
MATERIAL_CASE = ["scene=elastic_ball_3d", "scene.resolution=64"]
MATERIALS = ("fixed_corotated", "neo_hookean", "viscous", "snow", "sand", "von_mises", "nacc",
             "viscoplastic")


def bench_case(name: str, overrides: list[str], steps: int, workdir: Path) -> dict:
    common = overrides + [f"run.steps={steps}", "log.progress=false"]
    warm = execute(spec_for(overrides + ["run.steps=5", "log.every=1"]), workdir / f"{name}_warm")
    plain = timed(common + ["log.every=0", "log.scalars=false"], workdir / f"{name}_plain")
    t0 = plain["step_time_ms"]
    logged = None
    if RECORDING["on"]:
        logged = timed(common + ["log.every=1", "log.scalars=true"], workdir / f"{name}_logged")
        t1 = logged["step_time_ms"] + logged["log_time_ms"]
    return {
        "case": name, "overrides": overrides, "steps": steps,
        "particles": plain["particles"], "grid_nodes": plain["grid_nodes"],
        "compile_time_s": warm["compile_time_s"],
        "step_ms": t0,
        "particle_steps_per_s": plain["particles"] / (t0 * 1e-3),
        "logged_step_ms": logged and logged["step_time_ms"], "log_ms": logged and logged["log_time_ms"],
        "log_overhead": logged and t1 / t0 - 1.0,
    }


# the balls lowered onto the floor: their nodes reach the wall band from the first step
AT_FLOOR = {"ball_2d": ["scene.bodies.0.shape.center=[0.5,0.225]"],
            "ball_3d": ["scene.bodies.0.shape.center=[0.5,0.25,0.5]"]}


def bench_schemes(workdir: Path, steps: int | None) -> list[dict]:
    """The schemes on each ball, in flight and at the floor, in interleaved
    rounds per ball; the fastest median of each."""
    rows = []
    for case in ("ball_2d", "ball_3d"):
        runs = {(place, sch): CASES[case] + extra + [f"scheme={sch}", f"run.steps={steps or STEPS[case]}"] + QUIET
                for place, extra in (("in flight", []), ("at the floor", AT_FLOOR[case])) for sch in SCHEMES}
        best = interleaved(runs, [], workdir / f"schemes_{case}")
        for (place, sch), m in best.items():
            rows.append({"case": case, "place": place, "scheme": sch, "particles": m["particles"],
                         "step_ms": m["step_time_ms"],
                         "vs_empm": m["step_time_ms"] / best[place, "empm"]["step_time_ms"],
                         "update_ms": m["update_time_ms"], "updates": m["config_updates"]["total"]})
    return rows


FLUID_ROUNDS = 3  # interleaved rounds of the fluid runs; the fastest of each counts
FLUID_SCHEMES = {"empm": ["scheme=empm"], "aulmpm": ["scheme=aulmpm"],
                 "aulmpm_paper": ["scheme=aulmpm", "scheme.criterion=paper"]}


def bench_updates(workdir: Path) -> list[dict]:
    """EMPM, A-ULMPM (fluid defaults) and A-ULMPM with the paper's criterion
    on the 2D droplet and the 3D water drop, whole runs to the same end time,
    in interleaved rounds (a drift of the machine's speed hits all alike); per
    scheme the round with the least stepping time."""
    rows = []
    for scene, over in FLUIDS.items():
        best = interleaved({name: over + scheme + QUIET for name, scheme in FLUID_SCHEMES.items()}, [],
                           workdir / scene, FLUID_ROUNDS, by=loop_s, warm=None)
        for name, m in best.items():
            rows.append({"scene": scene, "scheme": name, "particles": m["particles"], "steps": m["steps"],
                         "tau": m["updates_per_1e4_steps"], "update_ms": m["update_time_ms"],
                         "step_ms": m["step_time_ms"], "loop_s": m["loop_time_s"],
                         "loop_vs_empm": m["loop_time_s"] / best["empm"]["loop_time_s"]})
    return rows


def bench_kernels(workdir: Path, steps: int) -> list[dict]:
    """Quadratic against compact per transfer and scheme, in turns (as bench_schemes)."""
    combos = [(tr, s, k) for tr in ("pic", "mls") for s in ("tlmpm", "empm")
              for k in ("quadratic", "compact")]

    best = interleaved({c: KERNEL_CASE + [f"scheme={c[1]}", f"kernel={c[2]}", f"kernel.transfer={c[0]}"] + QUIET
                        for c in combos}, [f"run.steps={steps}"], workdir / "kernels")
    return [{"transfer": tr, "scheme": s, "kernel": k, "particles": m["particles"],
             "grid_nodes": m["grid_nodes"], "step_ms": m["step_time_ms"]}
            for (tr, s, k), m in best.items()]


def bench_materials(workdir: Path, steps: int) -> list[dict]:
    """Every material on the 3D sphere, in turns (as bench_schemes)."""
    best = interleaved({mat: MATERIAL_CASE + [f"material={mat}"] + QUIET for mat in MATERIALS},
                       [f"run.steps={steps}"], workdir / "materials")
    return [{"material": mat, "particles": m["particles"], "step_ms": m["step_time_ms"]}
            for mat, m in best.items()]


INTEGRATOR_CASE = ["scene=elastic_ball_2d", "scene.size=paper", "material=fixed_corotated", "run.dt=2.5e-4"]
INTEGRATORS = {"explicit": ["integrator=explicit"], "implicit": ["integrator=implicit"],
               "semi_implicit": ["integrator=implicit", "integrator.newton_max=1",
                                 "integrator.line_search=false"]}
INTEGRATOR_ROUNDS = 2


def bench_integrators(workdir: Path) -> list[dict]:
    """Explicit, implicit and semi-implicit on the paper-size 2D ball at the
    same fixed step, whole runs in interleaved rounds; per integrator the
    round with the least stepping time."""
    best = interleaved({name: INTEGRATOR_CASE + over + QUIET for name, over in INTEGRATORS.items()},
                       ["run.duration=1.0"], workdir / "integrators", INTEGRATOR_ROUNDS, by=loop_s)
    base = best["explicit"]
    rows = []
    for name, m in best.items():
        mean = 1e3 * m["loop_time_s"] / m["steps"]
        implicit = m.get("implicit") or {}
        rows.append({"integrator": name, "particles": m["particles"], "steps": m["steps"],
                     "step_ms": m["step_time_ms"], "mean_ms": mean,
                     "vs_explicit": mean / (1e3 * base["loop_time_s"] / base["steps"]),
                     "newton": implicit.get("newton_mean"), "cg": implicit.get("cg_mean")})
    return rows


FUSED_CASES = {"ball_2d quadratic mls": CASES["ball_2d"],
               "sphere_3d quadratic mls": KERNEL_CASE,
               "sphere_3d quadratic pic": KERNEL_CASE + ["kernel.transfer=pic"],
               "sphere_3d compact mls": KERNEL_CASE + ["kernel=compact"],
               "sphere_3d compact pic": KERNEL_CASE + ["kernel=compact", "kernel.transfer=pic"]}
FUSED_ROUNDS = 3


def bench_fused(workdir: Path, steps: int) -> list[dict]:
    """EMPM with stencils located in P2G and G2P and the update in G2P
    (fused) against cached at an update pass, interleaved rounds, fastest
    median of each."""
    best = interleaved({(name, fuse): over + ["scheme=empm", "detect.action=off", f"run.fuse={fuse}"] + QUIET
                        for name, over in FUSED_CASES.items() for fuse in ("true", "false")},
                       [f"run.steps={steps}"], workdir / "fused", FUSED_ROUNDS)
    return [{"case": name, "particles": best[(name, "true")]["particles"],
             "fused_ms": best[(name, "true")]["step_time_ms"], "cached_ms": best[(name, "false")]["step_time_ms"]}
            for name in FUSED_CASES]


SYNC_EVERY = (1, 10)  # read-backs every k steps (mpm.stepping.driver): the CPU's default and CUDA's
SYNC_ROUNDS = 3


def bench_sync(workdir: Path, device: str) -> list[dict]:
    """The 2D ball and the 3D sphere (EMPM, step only, detection on) with the
    host reading back every step and every 10 steps (with the CUDA graph on
    CUDA), in interleaved rounds: ms per step, read-backs and kernel launches
    per step (the driver's own count, mpm.launch.Counter), the ratio to k = 1."""
    rows = []
    for case in ("ball_2d", "ball_3d"):
        runs = {k: CASES[case] + ["scheme=empm", f"run.sync_every={k}", f"run.steps={STEPS[case]}"] + QUIET
                for k in SYNC_EVERY}
        best = interleaved(runs, [], workdir / f"sync_{case}", SYNC_ROUNDS)
        for k, m in best.items():
            launches, memory, reads = scale.launches_per_step(spec_for(runs[k]), steps=50, sync_every=k)
            rows.append({"case": case, "sync_every": k, "graph": k > 1 and device.startswith("cuda"),
                         "particles": m["particles"], "grid_nodes": m["grid_nodes"], "step_ms": m["step_time_ms"],
                         "vs_k1": m["step_time_ms"] / best[1]["step_time_ms"], "reads": reads,
                         "launches": launches, "copies_fills": memory})
    return rows


TABLES = ("speed", "peers", "schemes", "updates", "kernels", "materials", "integrators", "fused", "sync", "stages",
          "profile", "precision", "paper", "scaling", "large", "sweep", "order", "checkpoint",
          "gpu-profile")
# tables in the default run: --no-<table> leaves one out
SKIPPABLE = {"peers": "peer-code (Taichi)", "schemes": "scheme", "updates": "update-cost", "kernels": "kernel",
             "materials": "material", "integrators": "integrator", "fused": "fused-against-cached EMPM",
             "sync": "read-backs every k steps", "stages": "optional-stage",
             "profile": "per-kernel profile", "precision": "precision"}


def main(argv=None) -> None:
    from ..config.arguments import Parser, output_file

    p = Parser(prog="python -m pipelines.bench", description=__doc__,
               formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("cases", nargs="*", default=list(CASES), help=f"subset of {', '.join(CASES)}")
    p.add_argument("--steps", type=int, default=None, help="steps per timed run")
    p.add_argument("--cold", action="store_true", help="compile into an empty kernel cache")
    p.add_argument("--json", type=Path, default=None, help="also write the results here")
    for table, what in SKIPPABLE.items():
        p.add_argument(f"--no-{table}", dest=table, action="store_false", help=f"skip the {what} table")
    p.add_argument("--genesis-python", default=os.environ.get("GENESIS_PYTHON"),
                   help="a Python with genesis-world installed: the peers table adds Genesis on the 3D ball "
                        "(CPU only; default: $GENESIS_PYTHON)")
    p.add_argument("--paper", action="store_true", help="add the A-ULMPM Table 2 scenes at the paper's size")
    p.add_argument("--scaling", action="store_true", help="add the 10K-1M particle scaling table")
    p.add_argument("--large", action="store_true", help="add the 1M and 10M particle sphere (for a GPU)")
    p.add_argument("--sweep", action="store_true", help="add the runs per hour of a 2N-job sweep on 1 and N workers")
    p.add_argument("--no-recording", dest="recording", action="store_false",
                   help="write no recordings (runs log to a sink that drops everything; the logged "
                        "columns of the speed table are left out): for a machine without rerun-sdk")
    p.add_argument("--only", default=None, help=f"comma-separated tables to run: {', '.join(TABLES)}")
    p.add_argument("--device", default=None, choices=("auto", "cpu", "cuda"),
                   help="the Warp device of every run (default: $MPM_DEVICE, else auto: CUDA where Warp finds a GPU)")
    p.add_argument("--profile-sizes", default=",".join(scale.LARGE),
                   help="gpu-profile: comma-separated sizes, 1M, 10M or a sphere resolution (default: 1M,10M)")
    p.set_defaults(speed=True, order=False, checkpoint=False, **{"gpu-profile": False})  # speed: the first (--only
    # may leave it out); order, checkpoint and gpu-profile: --only alone
    args = p.parse_args(argv)
    if args.steps is not None and args.steps < 1:
        p.error(f"--steps: {args.steps}; accepted: an integer >= 1")
    if args.json is not None and (problem := output_file("--json", args.json, ".json")):
        p.error(problem)
    if args.genesis_python and (problem := peers.genesis_python_problem(args.genesis_python)):
        p.error(f"--genesis-python: {args.genesis_python}: {problem}; accepted: a Python executable where "
                f"genesis-world is installed")
    sizes = [s for s in args.profile_sizes.split(",") if s]
    for s in sizes:
        try:
            gpu_profile.resolution_of(s)
        except ValueError as e:
            p.error(str(e))
    for c in args.cases:
        if c not in CASES:
            p.error(f"unknown case {c!r}; accepted: {', '.join(CASES)}")
    if args.only is not None:
        chosen = [t for t in args.only.split(",") if t]
        for t in chosen:
            if t not in TABLES:
                p.error(f"--only: unknown table {t!r}; accepted: {', '.join(TABLES)}")
        for t in TABLES:
            setattr(args, t, t in chosen)
    RECORDING["on"] = args.recording
    if args.device is not None:  # run.device's default, for every run below
        os.environ["MPM_DEVICE"] = args.device
    schema.register()
    with tempfile.TemporaryDirectory(prefix="mpm-bench-") as tmp:
        if args.cold:
            import warp as wp

            wp.config.kernel_cache_dir = str(Path(tmp) / "kernels")
        init_warp()
        import warp as wp

        device = spec_for(CASES["ball_2d"]).run.device  # run.device=auto: CUDA where Warp finds a GPU
        print(f"warp {wp.__version__}, device {device}, float32; median over the timed steps",
              file=sys.stderr)
        rows = ([bench_case(c, CASES[c], args.steps or STEPS[c], Path(tmp)) for c in args.cases]
                if args.speed else [])
        peer_rows = peers.bench_peers(Path(tmp), device) if args.peers else []
        genesis_rows = (peers.bench_genesis(Path(tmp), args.genesis_python) if args.peers and device == "cpu"
                        else [])
        schemes = bench_schemes(Path(tmp), args.steps) if args.schemes else []
        updates = bench_updates(Path(tmp)) if args.updates else []
        kernels = bench_kernels(Path(tmp), 40) if args.kernels else []
        materials = bench_materials(Path(tmp), 40) if args.materials else []
        integrators = bench_integrators(Path(tmp)) if args.integrators else []
        fused = bench_fused(Path(tmp), 40) if args.fused else []
        sync = bench_sync(Path(tmp), device) if args.sync else []
        stages = scale.bench_stages(Path(tmp)) if args.stages else []
        profile = scale.profile() if args.profile else []
        precisions = precision.bench_precision(Path(tmp), args.steps) if args.precision else []
        paper = scale.bench_paper(Path(tmp)) if args.paper else []
        scaling = scale.bench_scaling(Path(tmp)) if args.scaling else []
        large = scale.bench_large(energies=(True, False)) if args.large else []
        sweep = throughput.bench_sweep(Path(tmp)) if args.sweep else []
        orders = order.bench_order(device) if args.order else []
        ckpts = checkpoint.bench_checkpoint(Path(tmp)) if args.checkpoint else []
        where = gpu_profile.gpu_profile(sizes) if getattr(args, "gpu-profile") else []
    if rows:
        print(f"speed (EMPM, float32, {device})")
        print(f"{'case':<9} {'particles':>9} {'grid':>8} {'compile s':>9} {'ms/step':>8} "
              f"{'Mpart-steps/s':>13} {'logged ms':>9} {'+log ms':>8} {'log overhead':>12}")
    for r in rows:
        logged = (f"{r['logged_step_ms']:>9.3f} {r['log_ms']:>8.3f} {100 * r['log_overhead']:>11.0f}%"
                  if r["logged_step_ms"] is not None else f"{'-':>9} {'-':>8} {'-':>12}")
        print(f"{r['case']:<9} {r['particles']:>9,} {r['grid_nodes']:>8,} {r['compile_time_s']:>9.2f} "
              f"{r['step_ms']:>8.3f} {r['particle_steps_per_s'] / 1e6:>13.2f} {logged}")
    if peer_rows:
        peers.print_peers(peer_rows, device)
        if genesis_rows:
            peers.print_genesis(genesis_rows)
    if schemes:
        print("\nschemes on the 2D ball (128^2) and the 3D sphere (64^3), step only")
        print(f"{'case':<8} {'place':<13} {'scheme':<8} {'ms/step':>8} {'vs empm':>8} {'update ms/step':>15} "
              f"{'updates':>8}")
        for r in schemes:
            print(f"{r['case']:<8} {r['place']:<13} {r['scheme']:<8} {r['step_ms']:>8.3f} {r['vs_empm']:>8.2f} "
                  f"{r['update_ms']:>15.4f} {r['updates']:>8}")
    if updates:
        print("\nfluids to 0.5 s: configuration-update cost and total stepping time "
              f"(fastest of {FLUID_ROUNDS} interleaved rounds)")
        print(f"{'scene':<14} {'scheme':<13} {'particles':>9} {'steps':>6} {'tau':>8} {'update ms/step':>15} "
              f"{'ms/step':>8} {'loop s':>7} {'vs empm':>8}")
        for r in updates:
            print(f"{r['scene']:<14} {r['scheme']:<13} {r['particles']:>9,} {r['steps']:>6} {r['tau']:>8.1f} "
                  f"{r['update_ms']:>15.4f} {r['step_ms']:>8.3f} {r['loop_s']:>7.2f} {r['loop_vs_empm']:>7.2f}x")
        for scene in FLUIDS:
            e, a = (next(r for r in updates if r["scene"] == scene and r["scheme"] == n)
                    for n in ("empm", "aulmpm"))
            print(f"{scene}: update overhead EMPM / A-ULMPM: {e['update_ms'] / a['update_ms']:.2f}x")
    if kernels:
        print("\nkernels on the 3D sphere (64^3, neo-Hookean), step only")
        print(f"{'transfer':<9} {'scheme':<7} {'kernel':<10} {'particles':>9} {'nodes':>8} "
              f"{'ms/step':>8} {'speed-up':>9}")
        for r in kernels:
            quad = next(q for q in kernels if (q["transfer"], q["scheme"], q["kernel"])
                        == (r["transfer"], r["scheme"], "quadratic"))
            print(f"{r['transfer']:<9} {r['scheme']:<7} {r['kernel']:<10} {r['particles']:>9,} "
                  f"{r['grid_nodes']:>8,} {r['step_ms']:>8.3f} {quad['step_ms'] / r['step_ms']:>8.2f}x")
    if materials:
        base = materials[0]["step_ms"]
        print(f"\nmaterials on the 3D sphere (64^3, EMPM), step only, {materials[0]['particles']:,} particles")
        print(f"{'material':<16} {'ms/step':>8} {'vs fixed_corotated':>19}")
        for r in materials:
            print(f"{r['material']:<16} {r['step_ms']:>8.3f} {r['step_ms'] / base:>18.2f}x")
    if integrators:
        r0 = integrators[0]
        print(f"\nintegrators on the 2D ball (the paper's size, {r0['particles']:,} particles), 1 s at "
              f"dt = 2.5e-4 s, {r0['steps']} steps (fastest of {INTEGRATOR_ROUNDS} interleaved rounds)")
        print(f"{'integrator':<14} {'median ms/step':>14} {'mean ms/step':>12} {'vs explicit':>11} "
              f"{'Newton/step':>11} {'CG/step':>8}")
        for r in integrators:
            newton = f"{r['newton']:.2f}" if r["newton"] is not None else "-"
            cg = f"{r['cg']:.1f}" if r["cg"] is not None else "-"
            print(f"{r['integrator']:<14} {r['step_ms']:>14.3f} {r['mean_ms']:>12.3f} "
                  f"{r['vs_explicit']:>10.2f}x {newton:>11} {cg:>8}")
        print("the A-ULMPM paper (Table 2): implicit 0.0165 s / explicit 0.0148 s per step = 1.11x")
    if fused:
        print(f"\nEMPM stencils: located in the transfers (fused) against cached at every update, step only "
              f"(fastest of {FUSED_ROUNDS} interleaved rounds)")
        print(f"{'case':<26} {'particles':>9} {'fused ms':>9} {'cached ms':>10} {'speed-up':>9}")
        for r in fused:
            print(f"{r['case']:<26} {r['particles']:>9,} {r['fused_ms']:>9.3f} {r['cached_ms']:>10.3f} "
                  f"{r['cached_ms'] / r['fused_ms']:>8.2f}x")
    if sync:
        print(f"\nread-backs every k steps (EMPM, step only, detection on, {device}; fastest of {SYNC_ROUNDS} "
              "interleaved rounds; reads and launches per step counted over 50 steps)")
        print(f"{'case':<9} {'k':>3} {'graph':>6} {'particles':>9} {'grid':>8} {'ms/step':>8} {'vs k=1':>7} "
              f"{'reads/step':>10} {'launches/step':>13} {'copies/step':>11}")
        for r in sync:
            print(f"{r['case']:<9} {r['sync_every']:>3} {str(r['graph']):>6} {r['particles']:>9,} "
                  f"{r['grid_nodes']:>8,} {r['step_ms']:>8.3f} {r['vs_k1']:>6.2f}x {r['reads']:>10.2f} "
                  f"{r['launches']:>13.1f} {r['copies_fills']:>11.1f}")
    if stages:
        scale.print_stages(stages)
    if profile:
        scale.print_profile(profile)
    if orders:
        order.print_order(orders, device)
    if precisions:
        precision.print_precision(precisions)
    if paper:
        scale.print_paper(paper)
    if scaling:
        scale.print_scaling(scaling)
    if large:
        scale.print_large(large)
    if sweep:
        throughput.print_sweep(sweep)
    if ckpts:
        checkpoint.print_checkpoint(ckpts)
    if where:
        gpu_profile.print_gpu_profile(where)
    if args.json:
        args.json.write_text(json.dumps({"speed": rows, "schemes": schemes, "updates": updates,
                                         "peers": peer_rows + genesis_rows, "kernels": kernels, "materials": materials,
                                         "integrators": integrators, "fused": fused, "sync": sync,
                                         "stages": stages,
                                         "profile": profile, "order": orders, "precision": precisions, "paper": paper,
                                         "scaling": scaling, "large": large, "sweep": sweep,
                                         "checkpoint": ckpts, "gpu_profile": where}, indent=2) + "\n")


if __name__ == "__main__":
    main()
