"""Speed of the solver and of logging: ``python -m pipelines.bench``.

Each case runs through the same code path as ``pipelines.run``
(:func:`pipelines.runner.execute`), after a warm-up run, twice:
  * step only: no particles, no scalars (log.every=0, log.scalars=false);
  * logged: particles and dJ every step, scalars every step.
Reported per case: particles, grid nodes, compile (or cache load) time,
median ms per step, particle-steps per second, and the logging overhead
(logged step + logging time against the step-only time, same process).
``--cold`` compiles into an empty kernel cache to time a first compile.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from hydra import compose, initialize_config_dir

from . import schema
from .runner import execute
from .validate import resolve
from .warp_setup import init_warp

CONF = Path(__file__).resolve().parents[1] / "conf"

CASES = {
    "ball_2d": ["scene=elastic_ball_2d", "scene.resolution=128", "material=fixed_corotated"],
    "ball_3d": ["scene=elastic_ball_3d", "scene.resolution=64", "material=fixed_corotated"],
}
STEPS = {"ball_2d": 400, "ball_3d": 60}


def spec_for(overrides: list[str]):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return resolve(compose(config_name="config", overrides=overrides))


def bench_case(name: str, overrides: list[str], steps: int, workdir: Path) -> dict:
    common = overrides + [f"run.steps={steps}", "log.progress=false"]
    warm = execute(spec_for(overrides + ["run.steps=5", "log.every=1"]), workdir / f"{name}_warm")
    plain = execute(spec_for(common + ["log.every=0", "log.scalars=false"]), workdir / f"{name}_plain")
    logged = execute(spec_for(common + ["log.every=1", "log.scalars=true"]), workdir / f"{name}_logged")
    for m in (warm, plain, logged):
        if m["status"] != "completed":
            raise RuntimeError(f"{name}: {m['status']}: {m['reason']}")
    t0 = plain["step_time_ms"]
    t1 = logged["step_time_ms"] + logged["log_time_ms"]
    return {
        "case": name, "overrides": overrides, "steps": steps,
        "particles": plain["particles"], "grid_nodes": plain["grid_nodes"],
        "compile_time_s": warm["compile_time_s"],
        "step_ms": t0,
        "particle_steps_per_s": plain["particles"] / (t0 * 1e-3),
        "logged_step_ms": logged["step_time_ms"], "log_ms": logged["log_time_ms"],
        "log_overhead": t1 / t0 - 1.0,
    }


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("cases", nargs="*", default=list(CASES), help=f"subset of {', '.join(CASES)}")
    p.add_argument("--steps", type=int, default=None, help="steps per timed run")
    p.add_argument("--cold", action="store_true", help="compile into an empty kernel cache")
    p.add_argument("--json", type=Path, default=None, help="also write the results here")
    args = p.parse_args(argv)
    for c in args.cases:
        if c not in CASES:
            p.error(f"unknown case {c!r}; accepted: {', '.join(CASES)}")
    schema.register()
    with tempfile.TemporaryDirectory(prefix="mpm-bench-") as tmp:
        if args.cold:
            import warp as wp

            wp.config.kernel_cache_dir = str(Path(tmp) / "kernels")
        init_warp()
        import warp as wp

        print(f"warp {wp.__version__}, device cpu, float32; median over the timed steps",
              file=sys.stderr)
        rows = [bench_case(c, CASES[c], args.steps or STEPS[c], Path(tmp)) for c in args.cases]
    header = (f"{'case':<9} {'particles':>9} {'grid':>8} {'compile s':>9} {'ms/step':>8} "
              f"{'Mpart-steps/s':>13} {'logged ms':>9} {'+log ms':>8} {'log overhead':>12}")
    print(header)
    for r in rows:
        print(f"{r['case']:<9} {r['particles']:>9,} {r['grid_nodes']:>8,} {r['compile_time_s']:>9.2f} "
              f"{r['step_ms']:>8.3f} {r['particle_steps_per_s'] / 1e6:>13.2f} "
              f"{r['logged_step_ms']:>9.3f} {r['log_ms']:>8.3f} {100 * r['log_overhead']:>11.0f}%")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
