"""The precision table of ``python -m pipelines.bench``: what the
compensated sums of x and F (``run.compensate``, mpm.SolverOptions.compensate)
and float64 cost per step against plain float32, on the 2D ball, the 3D
sphere (EMPM and TLMPM, step only; float32 resolves them, so
``run.compensate`` null leaves them plain) and the small-deflection
cantilever (4 cells across the beam, where float32 does not: null
compensates), in interleaved rounds, fastest median of each."""

from __future__ import annotations

from pathlib import Path

from .runs import QUIET, interleaved

CASES = {
    "ball_2d": (["scene=elastic_ball_2d", "scene.resolution=128", "material=fixed_corotated"], 400),
    "ball_3d": (["scene=elastic_ball_3d", "scene.resolution=64", "material=fixed_corotated"], 60),
    "cantilever": (["scene=cantilever_stiff_2d"], 400),
}
VARIANTS = {"float32": ["run.precision=float32", "run.compensate=false"],
            "float32 compensated": ["run.precision=float32", "run.compensate=true"],
            "float64": ["run.precision=float64"]}
SCHEMES = ("empm", "tlmpm")
ROUNDS = 3


def bench_precision(workdir: Path, steps: int | None = None) -> list[dict]:
    """Per case and scheme, each variant's fastest median ms per step and its
    ratio to plain float32, measured in the same interleaved rounds."""
    rows = []
    for case, (over, n) in CASES.items():
        for scheme in SCHEMES:
            runs = {v: over + [f"scheme={scheme}", "detect.action=off"] + extra + QUIET
                    for v, extra in VARIANTS.items()}
            best = interleaved(runs, [f"run.steps={steps or n}"], workdir / f"precision_{case}_{scheme}", ROUNDS)
            base = best["float32"]["step_time_ms"]
            rows += [{"case": case, "scheme": scheme, "variant": v, "particles": m["particles"],
                      "step_ms": m["step_time_ms"], "vs_float32": m["step_time_ms"] / base} for v, m in best.items()]
    return rows


def print_precision(rows: list[dict]) -> None:
    print(f"\nprecision: plain float32, float32 with compensated sums of x and F, float64; step only "
          f"(fastest of {ROUNDS} interleaved rounds)")
    print(f"{'case':<11} {'scheme':<7} {'variant':<20} {'particles':>9} {'ms/step':>8} {'vs float32':>10}")
    for r in rows:
        print(f"{r['case']:<11} {r['scheme']:<7} {r['variant']:<20} {r['particles']:>9,} {r['step_ms']:>8.3f} "
              f"{r['vs_float32']:>9.2f}x")
