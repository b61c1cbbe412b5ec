"""A-ULMPM's trade-off: error against run time over its update rule.

The experiment ``+experiment=aulmpm_tradeoff`` runs, per scene, a fine EMPM
reference (the point ``reference``), EMPM at the run resolution and A-ULMPM
with several update rules (``conf/tradeoff/``), all to the same end time.

Error measure. A splashing fluid is chaotic: two runs that differ at round-off
put a given particle in different droplets after the impact, and the
reference has other particles anyway, so particle-to-particle distances
measure nothing. What must agree is where the mass is:

* shape error: the total-variation distance between the two mass
  distributions, E = 1/2 sum_b |f_b - f_ref,b|, with f_b the fraction of the
  mass deposited in bin b by linear (cloud-in-cell) weights on bins of side
  L / BINS (L the domain's first side). 0 for the same distribution, 1 for
  disjoint ones; insensitive to particle count and identity.
* centre-of-mass error |c - c_ref| [m].

The report plots the shape error against the wall time spent stepping,
marks the Pareto front, EMPM and the paper's (epsilon, eta) = (0.01, 0.01).
"""

from __future__ import annotations

import math

import numpy as np

from ..common import absent, md_table, pareto_front, pyplot, write_csv
from ..jobs import config_value
from ..registry import section

BINS = 16  # bins along the domain's first side
POINT_KEY = "tradeoff"  # the sweep's config group (conf/tradeoff/)
PAPER_POINT = "paper"  # the A-ULMPM paper's criterion with epsilon = eta = 0.01
REFERENCE_POINT = "reference"


def mass_distribution(x: np.ndarray, mass: np.ndarray | None, domain, bins: int = BINS) -> np.ndarray:
    """Fraction of the mass per bin (cloud-in-cell weights), bins of side
    domain[0] / bins over the whole domain; sums to 1."""
    x = np.asarray(x, dtype=np.float64)
    n, dim = x.shape
    m = np.ones(n) if mass is None else np.asarray(mass, dtype=np.float64)
    h = float(domain[0]) / bins
    shape = tuple(int(math.ceil(float(L) / h - 1e-9)) + 1 for L in domain[:dim])
    u = np.clip(x / h - 0.5, 0.0, np.array(shape) - 1.000001)  # bin centres at (i + 1/2) h
    i0 = np.floor(u).astype(np.int64)
    f = u - i0
    out = np.zeros(shape)
    for corner in range(2**dim):
        offs = np.array([(corner >> a) & 1 for a in range(dim)])
        w = m * np.prod(np.where(offs, f, 1.0 - f), axis=1)
        idx = np.minimum(i0 + offs, np.array(shape) - 1)
        np.add.at(out, tuple(idx.T), w)
    return out / out.sum()


def shape_error(x, mass, x_ref, mass_ref, domain, bins: int = BINS) -> float:
    """1/2 sum |f - f_ref| over the bins (see the module docstring)."""
    return 0.5 * float(np.abs(mass_distribution(x, mass, domain, bins)
                              - mass_distribution(x_ref, mass_ref, domain, bins)).sum())


def center_of_mass(x, mass) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    m = np.ones(len(x)) if mass is None else np.asarray(mass, dtype=np.float64)
    return (m[:, None] * x).sum(0) / m.sum()


@section(order=100)
def section_tradeoff(jobs: list, out) -> list[str]:
    """Report section for the jobs of a trade-off sweep (override +tradeoff):
    tradeoff.csv and tradeoff.png."""
    title = "A-ULMPM trade-off: error against run time"
    have = [j for j in jobs if POINT_KEY in j.overrides]
    if not have:
        return absent(title, "no job of a trade-off sweep (+tradeoff=...)")
    lines = [f"## {title}", "",
             f"Shape error (total-variation distance between the mass distributions on bins of "
             f"1/{BINS} of the domain, pipelines.tradeoff) and centre-of-mass error against the "
             f"point `{REFERENCE_POINT}` (fine EMPM) of the same scene at the same end time, "
             "against the wall time spent stepping ([tradeoff.csv](tradeoff.csv)).", ""]
    rows, plots, fronts = [], {}, []
    for scene in sorted({j.scene for j in have}):
        members = [j for j in have if j.scene == scene]
        refs = [j for j in members if j.overrides[POINT_KEY] == REFERENCE_POINT and j.completed]
        ref = refs[0].final_state() if refs else None
        domain = config_value(refs[0].config, "scene", "domain") if refs else None
        if ref is not None and domain is not None:  # binned once per scene
            f_ref = mass_distribution(ref["x"], ref.get("mass"), domain)
            c_ref = center_of_mass(ref["x"], ref.get("mass"))
        for j in sorted(members, key=lambda j: j.overrides[POINT_KEY]):
            point = j.overrides[POINT_KEY]
            s = j.final_state() if j.completed else None
            err = com = None
            if s is not None and ref is not None and domain is not None and point != REFERENCE_POINT \
                    and abs(s["time"] - ref["time"]) <= 1e-9 * max(1.0, ref["time"]):
                err = 0.5 * float(np.abs(mass_distribution(s["x"], s.get("mass"), domain) - f_ref).sum())
                com = float(np.linalg.norm(center_of_mass(s["x"], s.get("mass")) - c_ref))
            rows.append([scene, point, j.scheme, j.status, j.num("steps"), j.num("loop_time_s"),
                         j.num("updates_per_1e4_steps"), j.num("dt_reference_factor"), err, com])
            if err is not None and j.num("loop_time_s"):
                plots.setdefault(scene, []).append((point, j.num("loop_time_s"), err))
        if not refs:
            lines += [f"{scene}: no completed `{REFERENCE_POINT}` job, no errors.", ""]
    headers = ["scene", "point", "scheme", "status", "steps", "run time [s]", "updates / 1e4 steps",
               "dt / fresh dt", "shape error", "centre-of-mass error [m]"]
    write_csv(out / "tradeoff.csv", headers, rows)
    lines += md_table(headers, rows)
    if plots:
        plt = pyplot()
        fig, axes = plt.subplots(1, len(plots), figsize=(6.5 * len(plots), 5), squeeze=False)
        for ax, (scene, pts) in zip(axes[0], sorted(plots.items())):
            t = np.array([p[1] for p in pts])
            e = np.array([p[2] for p in pts])
            front = pareto_front(t, e)
            order = np.argsort(t[front])
            ax.plot(t[front][order], e[front][order], "k--", lw=1, label="Pareto front")
            for (name, ti, ei), on in zip(pts, front):
                marker = "s" if name == "empm" else ("*" if name == PAPER_POINT else "o")
                ax.plot(ti, ei, marker, ms=11 if marker == "*" else 7,
                        color="tab:red" if name == "empm" else ("tab:green" if on else "tab:blue"))
                ax.annotate(name, (ti, ei), fontsize=7, xytext=(3, 3), textcoords="offset points")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("run time [s] (stepping)")
            ax.set_ylabel("shape error against the fine EMPM reference")
            ax.set_title(f"{scene}: EMPM (square), the paper's (0.01, 0.01) (star)")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
            names = [p[0] for p, on in zip(pts, front) if on]
            fronts.append(f"{scene}: on the Pareto front: {', '.join(names)}.")
        fig.tight_layout()
        fig.savefig(out / "tradeoff.png", dpi=120)
        plt.close(fig)
        lines += ["![shape error against run time](tradeoff.png)", ""]
        for text in fronts:
            lines += [text, ""]
    return lines
