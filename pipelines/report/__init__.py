"""Summarise a Hydra multirun sweep: CSV tables, PNG plots and one ``report.md``.

    python -m pipelines.report <sweep dir> [--out DIR]

Every job directory below the sweep dir (any depth, found by its
``metrics.json``) is read together with ``.hydra/config.yaml``,
``.hydra/overrides.yaml`` and, when present, ``final_state.npz`` and
``recording.rrd``. Jobs with the same ``config_hash`` are merged (a completed
one is kept). The report has one section per analysis, each written only when
the sweep holds the data for it (one module each in
:mod:`pipelines.report.sections`, in the order of :mod:`pipelines.report.registry`),
among them:

runs.csv            one row per job: method, size, status, timings, errors, drifts
error_vs_time.png   error against run time with the Pareto front (pareto.csv)
convergence.png     error against grid spacing with fitted orders (convergence.csv)
update_cost.csv     configuration-update frequency and cost, EMPM/A-ULMPM reduction
speed.csv/.png      ms per step and particle-steps per second, kernel cost ratios
conservation.png    momentum drift over time net of the gravity and boundary impulse,
                    and angular-momentum drift (conservation.csv, momentum_net_drift.csv)
fracture.csv/.png   fraction of neighbouring particle pairs torn apart, fragments

A job's error is its analytic error (from ``metrics.json``) when the scene has
an analytic solution, otherwise its self-convergence error against the finest
job of the same scene and method that shares its particle set:
E = sqrt(sum_p |phi_p - phi_ref,p|^2 / n_p) for positions [m] and velocities [m/s]
(:mod:`pipelines.report.jobs`).

:class:`pipelines.sweeps.callback.ReportCallback` writes the report at the
end of a multirun when listed under ``hydra.callbacks``.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
from pathlib import Path

from . import sections
from .common import is_absent, label_styles
from .jobs import assign_errors, assign_labels, load_jobs
from .registry import Section, registered


def load_sections() -> list[Section]:
    """Every section of :mod:`pipelines.report.sections` (each of its modules
    imported: they register their sections), in report order."""
    for module in pkgutil.iter_modules(sections.__path__):
        importlib.import_module(f"{sections.__name__}.{module.name}")
    return registered()


def write_report(sweep_dir: Path, out: Path | None = None) -> Path:
    """Read the jobs of ``sweep_dir`` and write the tables, plots and report.md
    into ``out`` (default: the sweep dir); returns the path of report.md."""
    sweep_dir = Path(sweep_dir)
    out = Path(out) if out is not None else sweep_dir
    out.mkdir(parents=True, exist_ok=True)
    jobs, duplicates = load_jobs(sweep_dir)
    lines = ["# Sweep report", "", f"Sweep: `{sweep_dir}`", ""]
    if not jobs:
        lines += ["No job found (no metrics.json below the sweep directory).", ""]
    else:
        assign_labels(jobs)
        assign_errors(jobs)
        style = label_styles(sorted({j.label for j in jobs}))
        documents: dict[str, list[str]] = {}  # markdown files of their own: the sections they hold
        left_out = []  # sections without data in this sweep: their titles, named once at the end
        for section in load_sections():
            part = section(jobs=jobs, out=out, style=style, duplicates=duplicates)
            if part and is_absent(part):
                left_out.append(part[0].removeprefix("## "))
                continue
            if section.document is not None and part:
                documents.setdefault(section.document, []).extend(part)
            lines += part
        if left_out:
            lines += ["## Sections without data in this sweep", "", "; ".join(left_out) + ".", ""]
        for name, body in documents.items():
            title = Path(name).stem.replace("_", " ").capitalize()
            (out / name).write_text("\n".join([f"# {title}", ""] + body).rstrip() + "\n")
    path = out / "report.md"
    path.write_text("\n".join(lines).rstrip() + "\n")
    return path


def main(argv: list[str] | None = None) -> int:
    from ..config.arguments import Parser, output_dir

    parser = Parser(prog="python -m pipelines.report", description=(__doc__ or "").split("\n")[0])
    parser.add_argument("sweep_dir", type=Path, help="multirun sweep directory")
    parser.add_argument("--out", type=Path, default=None, help="output directory (default: the sweep dir)")
    args = parser.parse_args(argv)
    if not args.sweep_dir.is_dir():
        print(f"error: sweep_dir: {args.sweep_dir}: no such directory; accepted: a multirun sweep directory "
              "(multirun/<date>/<time>)", file=sys.stderr)
        return 2
    problem = output_dir("--out", args.out)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    print(write_report(args.sweep_dir, args.out))
    return 0
