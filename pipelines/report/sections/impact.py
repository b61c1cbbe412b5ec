"""The two-disk impact (``+experiment=impact``, conf/scene/two_disks.yaml):
per scheme, kernel and transfer, when contact starts and ends, the energy
kept after the disks separate, how close the disks' particles came, and the
momentum drift (impact.csv)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...recording.recordings import read
from ..common import absent, fmt, md_table, write_csv
from ..jobs import Job
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
    out = {"contact_start": None, "contact_end": None, "separated": None, "energy_kept": None}
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


@section(order=65)
def section_impact(jobs: list[Job], out: Path) -> list[str]:
    """impact.csv: contact times, energy kept and momentum drift of the
    two-disk jobs."""
    title = "Two elastic disks: contact and the energy kept"
    have = [j for j in jobs if j.scene == SCENE and j.data_file("recording.rrd") is not None]
    if not have:
        return absent(title, f"no {SCENE} job with a recording (+experiment=impact)")
    headers = ["scheme", "kernel", "transfer", "resolution", "status", "steps", "contact from [s]", "contact to [s]",
               "separated", "energy kept", "closest approach", "momentum drift"]
    rows = []
    for j in sorted(have, key=lambda j: (j.scheme, j.kernel, j.transfer, j.resolution or 0)):
        rec = read(j.data_file("recording.rrd"))  # (two small disks: their frames are small)
        f = impact_figures(rec.scalars, rec.clock)
        closest = closest_approach(rec.positions, rec.body)
        rows.append([j.scheme, j.kernel, j.transfer, j.resolution, j.status, j.metrics.get("steps"), fmt(f["contact_start"], 3),
                     fmt(f["contact_end"], 3), {None: "", True: "yes", False: "no"}[f["separated"]],
                     fmt(f["energy_kept"], 3), fmt(closest, 3), fmt(j.metrics.get("momentum_drift"), 2)])
    write_csv(out / "impact.csv", headers, rows)
    return [f"## {title}", "",
            "Sulsky, Chen and Schreyer (1994): two elastic disks meet and separate; the elastic "
            "continuum keeps all its energy, and its disks (0.5 sqrt(2) m apart, radius 0.2 m, closing "
            "at 0.2 sqrt(2) m/s) touch at t = 1.086 s. Per scheme, kernel and transfer: the first and last time a "
            "body node is in contact (mpm.contact), whether the disks separated by the end, the total "
            "energy after the last contact over the initial one, the closest approach of two particles "
            "of the two disks over the logged frames in particle spacings (below 1: the disks overlap), "
            "and the momentum drift "
            "([impact.csv](impact.csv)).", ""] + md_table(headers, rows) + [""]
