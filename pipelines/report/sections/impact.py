"""The two-disk impact (``+experiment=impact``, ``+experiment=impact_shared``,
conf/scene/two_disks.yaml): per scheme, contact, kernel and transfer, when
contact starts and ends, the energy kept after the disks separate, how close
the disks' particles came, and the momentum drift (impact.csv)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from mpm.kernels import KERNELS

from ...recording.recordings import read
from ..common import absent, add_image, fmt, md_table, pyplot, write_csv
from ..jobs import Job, config_value
from ..registry import section

SCENE = "two_disks"


def impact_figures(scalars: dict, clock: tuple) -> dict:
    """From a recording's scalar rows (``scalars[name] = (steps, values)``,
    ``clock = (steps, times)``): the first and last time with a body node in
    contact [s] (``contact_nodes`` > 0), whether the disks separated (no
    contact in the last row), and the energy kept: the mean total energy
    over the rows after the last contact over the first row's (None without
    a separation)."""
    steps, contact = (np.asarray(a, float) for a in scalars.get("contact_nodes", ((), ())))
    e_steps, energy = (np.asarray(a, float) for a in scalars.get("total_energy", ((), ())))
    times = dict(zip(np.asarray(clock[0], float).tolist(), np.asarray(clock[1], float).tolist()))
    out: dict[str, Any] = {"contact_start": None, "contact_end": None, "separated": None, "energy_kept": None}
    if not len(steps) or not len(e_steps):
        return out
    touching = steps[contact > 0]
    if len(touching):
        out["contact_start"] = times.get(float(touching.min()))
        out["contact_end"] = times.get(float(touching.max()))
    out["separated"] = bool(len(touching)) and bool(contact[np.argmax(steps)] == 0)
    if out["separated"]:
        after = energy[(e_steps > touching.max()) & np.isfinite(energy)]  # (an unstable run's last rows)
        first = energy[np.argmin(e_steps)]
        if len(after) and first > 0:
            out["energy_kept"] = float(after.mean() / first)
    return out


def closest_approach(positions: list, body: np.ndarray | None, max_pairs: int = 4_000_000) -> float | None:
    """The smallest distance between a particle of body 0 and one of body 1
    over the logged frames, over the particle spacing (the smallest distance
    between two particles of body 0 in the first frame): below 1, particles
    of the two disks came closer than neighbours within one, i.e. the bodies
    overlap by about (1 - it) spacings. None without frames or with more than
    ``max_pairs`` pairs a frame."""
    if body is None or not positions:
        return None
    a, b = body == 0, body == 1
    if a.sum() < 2 or not b.any() or a.sum() * b.sum() > max_pairs:
        return None

    def pairwise_min(p, q):
        return float(np.sqrt(((p[:, None, :] - q[None, :, :]) ** 2).sum(-1)).min())

    first = positions[0][a]
    d = np.sqrt(((first[:, None, :] - first[None, :, :]) ** 2).sum(-1))
    spacing = float(d[d > 0].min())
    return min(pairwise_min(x[a], x[b]) for x in positions if len(x) == len(body)) / spacing


def stencil_contact(steps, positions: list, body: np.ndarray | None, reach: float) -> tuple:
    """The contact rows of a run on one shared grid (``scene.contact=shared``,
    which has no contact pass to count): per logged frame, 1 where a particle
    of body 0 and one of body 1 are closer than ``reach`` [m] along every
    axis (their stencils may share a grid node, through which the bodies
    interact), else 0. ``(frame steps, flags)``, empty without frames."""
    if body is None or not positions:
        return np.zeros(0), np.zeros(0)
    a, b = body == 0, body == 1
    flags = [float(np.abs(x[a][:, None, :] - x[b][None, :, :]).max(-1).min() < reach) if len(x) == len(body) else 0.0
             for x in positions]
    return np.asarray(steps, float)[:len(flags)], np.asarray(flags)


def contact_of(j: Job) -> str:
    """The job's contact between bodies (``scene.contact``)."""
    return str(config_value(j.config, "scene", "contact") or j.overrides.get("scene.contact") or "frictionless")


def transfer_of(j: Job) -> str:
    """The transfer, with the PIC/FLIP blend's FLIP share."""
    flip = config_value(j.config, "kernel", "flip")
    return f"{j.transfer} {float(flip):g}" if j.transfer == "flip" and flip is not None else j.transfer


@section(order=65)
def section_impact(jobs: list[Job], out: Path) -> list[str]:
    """impact.csv: contact times, energy kept and momentum drift of the
    two-disk jobs."""
    title = "Two elastic disks: contact and the energy kept"
    have = [j for j in jobs if j.scene == SCENE and j.data_file("recording.rrd") is not None]
    if not have:
        return absent(title, f"no {SCENE} job with a recording (+experiment=impact)")
    headers = ["scheme", "contact", "kernel", "transfer", "resolution", "status", "steps", "contact from [s]",
               "contact to [s]", "separated", "energy kept", "closest approach", "momentum drift"]
    rows, curves = [], []
    for j in sorted(have, key=lambda j: (j.scheme, contact_of(j), j.kernel, transfer_of(j), j.resolution or 0)):
        path = j.data_file("recording.rrd")
        assert path is not None  # have: jobs with one
        rec = read(path)  # (two small disks: their frames are small)
        scalars, contact, transfer = rec.scalars, contact_of(j), transfer_of(j)
        if contact == "shared" and j.kernel in KERNELS and j.dx:
            # one grid: the disks interact while their stencils share a node (support x dx apart per axis)
            scalars = dict(scalars, contact_nodes=stencil_contact(rec.steps, rec.positions, rec.body,
                                                                  KERNELS[j.kernel].support * j.dx))
        f = impact_figures(scalars, rec.clock)
        closest = closest_approach(rec.positions, rec.body)
        curves.append(Curves(f"{j.scheme} {contact} {j.kernel} {transfer} {j.resolution}", j.transfer, contact,
                             f["energy_kept"] if j.completed else None, energy_curves(rec.scalars, rec.clock)))
        rows.append([j.scheme, contact, j.kernel, transfer, j.resolution, j.status, j.metrics.get("steps"),
                     fmt(f["contact_start"], 3), fmt(f["contact_end"], 3),
                     {None: "", True: "yes", False: "no"}[f["separated"]], fmt(f["energy_kept"], 3),
                     fmt(closest, 3), fmt(j.metrics.get("momentum_drift"), 2)])
    write_csv(out / "impact.csv", headers, rows)
    lines = [f"## {title}", "",
            "Sulsky, Chen and Schreyer (1994): two elastic disks meet and separate; the elastic "
            "continuum keeps all its energy, and its disks (0.5 sqrt(2) m apart, radius 0.2 m, closing "
            "at 0.2 sqrt(2) m/s) touch at t = 1.086 s. Per scheme, contact, kernel and transfer: the first and "
            "last time a body node is in contact (mpm.contact; on one shared grid, the first and last logged "
            "frame where the disks' particles are within the kernel's support of each other), whether the "
            "disks separated by the end, the total "
            "energy after the last contact over the initial one, the closest approach of two particles "
            "of the two disks over the logged frames in particle spacings (below 1: the disks overlap), "
            "and the momentum drift "
            "([impact.csv](impact.csv)).", ""] + md_table(headers, rows) + [""]
    if plot_energy(out / "impact_energy.png", curves):
        add_image(lines, "impact_energy.png", "energy against time: every job's total; the best job's kinetic, "
                                              "elastic and total")
    return lines


def energy_curves(scalars: dict, clock: tuple) -> dict:
    """``{"kinetic", "elastic", "total"}: (times [s], energies [J])`` of a
    recording's scalar rows (the names it has)."""
    times = dict(zip(np.asarray(clock[0], float).tolist(), np.asarray(clock[1], float).tolist()))
    curves = {}
    for key, name in (("kinetic", "kinetic_energy"), ("elastic", "elastic_energy"), ("total", "total_energy")):
        if name in scalars:
            steps, values = (np.asarray(a, float) for a in scalars[name])
            t = np.array([times.get(s, np.nan) for s in steps.tolist()])
            curves[key] = (t, values)
    return curves


class Curves(NamedTuple):
    """One job's energy curves for :func:`plot_energy`."""

    label: str
    transfer: str
    contact: str
    kept: float | None  # energy kept, None unless the job completed
    energy: dict  # energy_curves


def plot_energy(path: Path, curves: list[Curves]) -> bool:
    """Left: every job's total energy over its initial against time; right:
    the kinetic, elastic and total energy of the completed job that kept the
    most. False (no file) without a total energy."""
    curves = [c for c in curves if "total" in c.energy and len(c.energy["total"][1])]
    if not curves:
        return False
    plt = pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    # many jobs: coloured by transfer, dashed on one shared grid, one legend entry each
    kinds = sorted({c.transfer for c in curves}) if len(curves) > 12 else None
    seen = set()
    for c in curves:
        t, e = c.energy["total"]
        if kinds is None:
            left.plot(t, e / e[0], lw=0.8, label=c.label)
            continue
        key = (c.transfer, c.contact)
        left.plot(t, e / e[0], lw=0.8, color=f"C{kinds.index(c.transfer)}", ls="--" if c.contact == "shared" else "-",
                  label=None if key in seen else f"{c.transfer}, {c.contact}")
        seen.add(key)
    left.set(xlabel="time [s]", ylabel="total energy / initial", title="every job", ylim=(0, 1.1))
    left.legend(fontsize=6, loc="lower left")
    best = max(curves, key=lambda c: -1.0 if c.kept is None else c.kept)
    for key in ("kinetic", "elastic", "total"):
        if key in best.energy:
            right.plot(*best.energy[key], label=key)
    right.set(xlabel="time [s]", ylabel="energy [J]", title=f"{best.label} (kept {fmt(best.kept, 3)})")
    right.legend(loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return True
